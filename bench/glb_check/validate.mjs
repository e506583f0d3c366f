// Validate a .glb with the Khronos glTF validator; print the summary, exit 1 on any error or warning.
import { readFileSync } from "node:fs";
import validator from "gltf-validator";

const path = process.argv[2];
if (!path) {
  console.error("usage: node validate.mjs FILE.glb");
  process.exit(2);
}
const report = await validator.validateBytes(new Uint8Array(readFileSync(path)), {
  maxIssues: 50,
});
const i = report.issues;
console.log(
  JSON.stringify({
    file: path,
    validator: report.validatorVersion,
    errors: i.numErrors,
    warnings: i.numWarnings,
    infos: i.numInfos,
    hints: i.numHints,
    messages: i.messages.filter((m) => m.severity <= 1).slice(0, 10),
    vertices: report.info?.totalVertexCount,
    triangles: report.info?.totalTriangleCount,
  })
);
process.exit(i.numErrors + i.numWarnings > 0 ? 1 : 0);
