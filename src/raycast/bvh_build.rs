//! Building a [`Bvh`]: a binary tree by binned SAH (parallel over subtrees with rayon), then
//! collapsed to W-wide nodes by repeatedly opening the child with the largest surface area.

use super::bvh::{Bvh, Node, EMPTY, LEAF, LEAF_SHIFT, STACK};
use super::triangle::Tri4;

/// Triangles per [`Tri4`] block; sets of at most this many always become a leaf.
const MAX_LEAF: usize = 4;
/// Sets of up to this many triangles become a leaf (of up to four blocks) when the SAH says
/// that is cheaper than splitting them. Measured on the phantom lumen (1 thread, per
/// CPU-second): leaves of at most 4 / 8 / 16 / 24 / 32 triangles traced random rays at about
/// 2.3 / 2.5 / 3.2 / 3.3 / 3.1 Mrays/s and camera packets at 11.4 / 11.9 / 12.3 / 12.5 / 12.5.
const MAX_LEAF_SAH: usize = 16;

/// SAH cost of traversing a node, relative to testing one block of four triangles (tuned with
/// the figures above: 1 and 4 were slower than 2).
const TRAV_COST: f32 = 2.0;
/// Number of SAH bins per axis.
const BINS: usize = 16;
/// Subtrees smaller than this are built on the current thread.
const PAR_MIN: usize = 4096;

#[derive(Clone, Copy, Debug)]
struct Aabb {
    min: [f32; 3],
    max: [f32; 3],
}

impl Aabb {
    const EMPTY: Aabb = Aabb {
        min: [f32::INFINITY; 3],
        max: [f32::NEG_INFINITY; 3],
    };
    #[inline]
    fn grow(&mut self, o: &Aabb) {
        for a in 0..3 {
            self.min[a] = self.min[a].min(o.min[a]);
            self.max[a] = self.max[a].max(o.max[a]);
        }
    }
    #[inline]
    fn grow_p(&mut self, p: [f32; 3]) {
        self.grow(&Aabb { min: p, max: p });
    }
    #[inline]
    fn half_area(&self) -> f32 {
        let d = [
            self.max[0] - self.min[0],
            self.max[1] - self.min[1],
            self.max[2] - self.min[2],
        ];
        if d[0] < 0.0 {
            return 0.0;
        }
        d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
    }
}

/// A binary build node.
enum BNode {
    Leaf {
        bbox: Aabb,
        start: usize,
        count: usize,
    },
    Inner {
        bbox: Aabb,
        kids: Box<[BNode; 2]>,
    },
}

impl BNode {
    fn bbox(&self) -> &Aabb {
        match self {
            BNode::Leaf { bbox, .. } | BNode::Inner { bbox, .. } => bbox,
        }
    }
}

struct Prim {
    bbox: Aabb,
    centroid: [f32; 3],
    id: u32,
}

/// Build the W-wide BVH over triangles given as vertex triples (mm). Returns `None` when the
/// tree would be deeper than the traversal stack allows (pathological input).
pub(crate) fn build<const W: usize>(tris: &[[[f32; 3]; 3]]) -> Option<Bvh<W>> {
    if tris.is_empty() {
        return Some(Bvh::default());
    }
    let mut prims: Vec<Prim> = tris
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let mut b = Aabb::EMPTY;
            for p in t {
                b.grow_p(*p);
            }
            let c = [
                0.5 * (b.min[0] + b.max[0]),
                0.5 * (b.min[1] + b.max[1]),
                0.5 * (b.min[2] + b.max[2]),
            ];
            Prim {
                bbox: b,
                centroid: c,
                id: i as u32,
            }
        })
        .collect();
    let root = build_rec(&mut prims, 0);
    let mut out = Bvh::<W>::default();
    let depth = match &root {
        BNode::Leaf { bbox, start, count } => {
            // A single leaf: wrap it in one node so traversal always starts at a node.
            out.nodes.push(empty_node());
            let h = push_leaf(&mut out, tris, &prims[*start..*start + *count]);
            set_child(&mut out.nodes[0], 0, bbox, h);
            1
        }
        BNode::Inner { .. } => collapse(&root, &mut out, tris, &prims, 1),
    };
    out.nodes = huge_copy(&out.nodes);
    out.leaves = huge_copy(&out.leaves);
    // Each level pushes at most W - 1 entries; leaf handles index blocks with LEAF_SHIFT bits.
    (depth * (W - 1) < STACK && out.leaves.len() < 1 << LEAF_SHIFT).then_some(out)
}

fn build_rec(prims: &mut [Prim], offset: usize) -> BNode {
    let mut bbox = Aabb::EMPTY;
    let mut cbox = Aabb::EMPTY;
    for p in prims.iter() {
        bbox.grow(&p.bbox);
        cbox.grow_p(p.centroid);
    }
    let n = prims.len();
    // A leaf block tests four triangles at the cost of about one: never split below four.
    if n <= MAX_LEAF {
        return BNode::Leaf {
            bbox,
            start: offset,
            count: n,
        };
    }
    let split = best_split(prims, &cbox);
    if n <= MAX_LEAF_SAH {
        let blocks = n.div_ceil(MAX_LEAF) as f32;
        let leaf = blocks * bbox.half_area();
        if split.is_none_or(|s| leaf <= TRAV_COST * bbox.half_area() + s.2) {
            return BNode::Leaf {
                bbox,
                start: offset,
                count: n,
            };
        }
    }
    let mid = match split {
        Some((axis, bin, _)) => {
            let lo = cbox.min[axis];
            let scale = BINS as f32 / (cbox.max[axis] - lo);
            let m = partition(prims, |p| bin_of(p.centroid[axis], lo, scale) <= bin);
            if m == 0 || m == n {
                n / 2
            } else {
                m
            }
        }
        // All centroids coincide: split in the middle of the list.
        None => n / 2,
    };
    let (l, r) = prims.split_at_mut(mid);
    let (a, b) = if n >= PAR_MIN {
        rayon::join(|| build_rec(l, offset), || build_rec(r, offset + mid))
    } else {
        (build_rec(l, offset), build_rec(r, offset + mid))
    };
    BNode::Inner {
        bbox,
        kids: Box::new([a, b]),
    }
}

#[inline]
fn bin_of(c: f32, lo: f32, scale: f32) -> usize {
    (((c - lo) * scale) as usize).min(BINS - 1)
}

/// Best (axis, last bin of the left side, SAH cost) over all axes, or `None` if the centroid box is flat.
fn best_split(prims: &[Prim], cbox: &Aabb) -> Option<(usize, usize, f32)> {
    let mut best: Option<(usize, usize, f32)> = None;
    for axis in 0..3 {
        let lo = cbox.min[axis];
        let ext = cbox.max[axis] - lo;
        // Also skips a NaN extent.
        if ext.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            continue;
        }
        let scale = BINS as f32 / ext;
        let mut boxes = [Aabb::EMPTY; BINS];
        let mut counts = [0usize; BINS];
        for p in prims {
            let b = bin_of(p.centroid[axis], lo, scale);
            boxes[b].grow(&p.bbox);
            counts[b] += 1;
        }
        // Sweep from the right for suffix areas, then from the left.
        let mut right_area = [0f32; BINS];
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0;
        let mut right_cnt = [0usize; BINS];
        for i in (1..BINS).rev() {
            acc.grow(&boxes[i]);
            cnt += counts[i];
            right_area[i] = acc.half_area();
            right_cnt[i] = cnt;
        }
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0;
        for i in 0..BINS - 1 {
            acc.grow(&boxes[i]);
            cnt += counts[i];
            if cnt == 0 || right_cnt[i + 1] == 0 {
                continue;
            }
            // Leaves are tested four triangles at a time: count in blocks of four (as Embree).
            let blocks = |n: usize| n.div_ceil(MAX_LEAF) as f32;
            let cost = blocks(cnt) * acc.half_area() + blocks(right_cnt[i + 1]) * right_area[i + 1];
            if best.is_none_or(|b| cost < b.2) {
                best = Some((axis, i, cost));
            }
        }
    }
    best
}

fn partition(prims: &mut [Prim], left: impl Fn(&Prim) -> bool) -> usize {
    let mut i = 0;
    let mut j = prims.len();
    while i < j {
        if left(&prims[i]) {
            i += 1;
        } else {
            j -= 1;
            prims.swap(i, j);
        }
    }
    i
}

fn empty_node<const W: usize>() -> Node<W> {
    let mut b = [[f32::INFINITY; W]; 6];
    for v in &mut b[3..] {
        *v = [f32::NEG_INFINITY; W];
    }
    Node {
        b,
        child: [EMPTY; W],
    }
}

fn set_child<const W: usize>(n: &mut Node<W>, j: usize, bbox: &Aabb, handle: u32) {
    for a in 0..3 {
        n.b[a][j] = bbox.min[a];
        n.b[3 + a][j] = bbox.max[a];
    }
    n.child[j] = handle;
}

fn push_leaf<const W: usize>(out: &mut Bvh<W>, tris: &[[[f32; 3]; 3]], prims: &[Prim]) -> u32 {
    let first = out.leaves.len();
    for block in prims.chunks(MAX_LEAF) {
        let mut t = Tri4::default();
        for j in 0..4 {
            // Padding lanes repeat the last triangle: a duplicate never changes the nearest hit.
            let p = &block[j.min(block.len() - 1)];
            let tri = &tris[p.id as usize];
            for (i, vert) in tri.iter().enumerate() {
                for (lane, &c) in t.v[i].iter_mut().zip(vert) {
                    lane.as_array_mut()[j] = c;
                }
            }
            t.id[j] = p.id;
        }
        out.leaves.push(t);
    }
    let extra = (out.leaves.len() - first - 1) as u32;
    first as u32 | extra << LEAF_SHIFT | LEAF
}

/// Turn binary inner node `b` into a W-wide node; returns the depth of the subtree.
fn collapse<const W: usize>(
    b: &BNode,
    out: &mut Bvh<W>,
    tris: &[[[f32; 3]; 3]],
    prims: &[Prim],
    depth: usize,
) -> usize {
    let BNode::Inner { kids, .. } = b else {
        unreachable!("collapse is called on inner nodes")
    };
    let mut open: Vec<&BNode> = vec![&kids[0], &kids[1]];
    while open.len() < W {
        // Open the inner child with the largest surface area (most likely to be entered).
        let pick = open
            .iter()
            .enumerate()
            .filter(|(_, c)| matches!(c, BNode::Inner { .. }))
            .max_by(|x, y| x.1.bbox().half_area().total_cmp(&y.1.bbox().half_area()))
            .map(|(i, _)| i);
        let Some(i) = pick else { break };
        let BNode::Inner { kids, .. } = open.swap_remove(i) else {
            unreachable!()
        };
        open.push(&kids[0]);
        open.push(&kids[1]);
    }
    let idx = out.nodes.len();
    out.nodes.push(empty_node());
    let mut deepest = depth;
    for (j, c) in open.iter().enumerate() {
        let h = match c {
            BNode::Leaf { start, count, .. } => {
                push_leaf(out, tris, &prims[*start..*start + *count])
            }
            BNode::Inner { .. } => {
                let h = out.nodes.len() as u32;
                deepest = deepest.max(collapse(c, out, tris, prims, depth + 1));
                h
            }
        };
        set_child(&mut out.nodes[idx], j, c.bbox(), h);
    }
    deepest
}

/// Copy `v` into a fresh allocation backed by transparent huge pages where the OS allows
/// (Linux, THP in "madvise" mode): traversal jumps across megabytes of nodes, and 2 MiB pages
/// remove most TLB misses. Elsewhere, or if the advice is refused, a plain copy.
fn huge_copy<T: Copy>(v: &[T]) -> Vec<T> {
    let mut out: Vec<T> = Vec::with_capacity(v.len());
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let start = out.as_ptr() as usize;
        let end = start + std::mem::size_of_val(v);
        let (a, b) = (start.next_multiple_of(HUGE), end / HUGE * HUGE);
        if b > a {
            // SAFETY: [a, b) lies inside our own untouched allocation; madvise only gives advice.
            unsafe { libc::madvise(a as *mut libc::c_void, b - a, libc::MADV_HUGEPAGE) };
        }
    }
    out.extend_from_slice(v);
    out
}
