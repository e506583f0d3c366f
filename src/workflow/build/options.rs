//! The options of the whole build: every stage's options with their defaults (the one place
//! each default number is written; the command line takes its defaults from here).

use crate::selection::SelectionOptions;
use crate::shading::calibrated::{CalibratedOptions, PoolOptions, ScopeLight};
use crate::shading::indirect::InterreflectionMode;
use crate::shading::paper::FitOptions;
use crate::shading::{SampleOptions, ShadingKind};
use crate::texture::atlas::AtlasOptions;
use crate::texture::fusion::{FusionMethod, FusionOptions, DEFAULT_WEIGHT_EXPONENT};
use crate::texture::synthesis::SynthesisOptions;
use crate::workflow::segment::SegmentCommandOptions;

/// Most frames a build uses by default (`--max-frames`).
pub const DEFAULT_MAX_FRAMES: usize = 200;

/// Options of the whole build; every stage's options with their defaults.
#[derive(Clone, Debug)]
pub struct BuildOptions {
    /// Segmentation and lumen mesh.
    pub segment: SegmentCommandOptions,
    /// Texture atlas (texel size in mm, gutter).
    pub atlas: AtlasOptions,
    /// Which pixels obey the shading model.
    pub samples: SampleOptions,
    /// The Psi fit.
    pub fit: FitOptions,
    /// De-lighting and fusion.
    pub fusion: FusionOptions,
    /// What the texture holds where no frame saw the wall (`--unseen`).
    pub unseen: SynthesisOptions,
    /// Which shading model de-lights the texture and shades new views (`None`: the one that
    /// predicts held-out frames better, decided by cross-validation).
    pub shading: Option<ShadingKind>,
    /// The calibrated light fit.
    pub calibrated: CalibratedOptions,
    /// The frame whose gain is 1 in the calibrated light (`None`: the middle frame;
    /// `calibrated.reference_frame` is ignored).
    pub calibrated_reference: Option<usize>,
    /// Pooling of the calibrated fit's samples.
    pub pool: PoolOptions,
    /// Most samples pooled over the whole video (fewer per frame for long videos; at least
    /// 1000 per frame).
    pub max_pooled_samples: usize,
    /// Rounds, right after the uniform-albedo fit, of refitting the calibrated light and its
    /// gains with each pixel's albedo predicted from its colour
    /// (`shading::chroma_albedo`; 0 keeps the uniform albedo).
    pub chroma_refits: usize,
    /// How the calibrated light models inter-reflection (`--interreflection`).
    pub interreflection: InterreflectionMode,
    /// Grid nodes across each frame the gathered inter-reflection is gathered at.
    pub gather_nodes: usize,
    /// Hemisphere rays per node of the gathered inter-reflection.
    pub gather_rays: usize,
    /// Test each bounce point's visibility from the light (one shadow ray per ray).
    pub gather_visibility: bool,
    /// Rounds of correcting the calibrated light's gains against a texture fused with them.
    pub refine_gains: usize,
    /// The textures those corrections and the light's refits compare against are fused on one
    /// atlas texel of every `k × k` block (1: every texel); their passes cost about 1/k².
    pub consensus_texel_factor: u32,
    /// Rounds, after those, of refitting the calibrated light's shape (rho, s, kappa) with each
    /// sample's albedo from a texture fused with it, each followed by one more gain correction
    /// (`workflow::light_refine`).
    pub refine_light: usize,
    /// Hold out every k-th frame for the cross-validation (0: no cross-validation).
    pub cross_validate_every: usize,
    /// Most frames held out.
    pub cross_validate_max_frames: usize,
    /// Working resolution of the fits, the light, the cross-validation and the registration:
    /// the frames reduced by 2^level (`None`: chosen from the texel size and the camera,
    /// `BuildScene::prepare`). The texture is always fused from full-resolution pixels.
    pub working_level: Option<usize>,
    /// Memory for depth buffers kept between passes (bytes); beyond it frames are ray cast again.
    pub depth_cache_bytes: usize,
    /// Frame selection (`selection.max_frames` = 0: every frame, no selection).
    pub selection: SelectionOptions,
    /// Trust the given poses, or refine them against the CT first.
    pub poses: PosesMode,
    /// Most rounds of the registration (light + texture, then every frame's pose).
    pub registration_rounds: usize,
    /// Rounds 0, N, 2N, ... register against the geometry, the others against the texture.
    /// The texture follows the poses it was fused from, so it cannot see an error every frame
    /// shares (a turn about the airway's axis, a shift along it); a geometry round after the
    /// texture rounds measures that again from poses the texture rounds made consistent
    /// (BENCHMARKS.md, issue 16).
    pub registration_geometry_every: usize,
    /// From this round on, the geometry rounds are shading rounds
    /// ([`crate::registration::RoundKind::Shading`]): the frames are also divided by the
    /// texture's albedo seen from their poses, which helps only once the texture rounds have
    /// made the poses consistent (demo phantom, 1.5 mm / 2 deg: BENCHMARKS.md, session 19).
    pub registration_shading_from: usize,
    /// After the rounds, every frame they did not flag is refined once more with all the
    /// others at once, the albedo eliminated ([`crate::registration::joint`]): the rounds
    /// leave an error that neighbouring frames share and the texture fused from them follows,
    /// which a frame registered on its own against that texture cannot see.
    pub registration_joint: bool,
    /// A geometry round is run again (within `registration_rounds`) while more than this share
    /// of its frames are outliers, their corrections departing from their neighbours': the
    /// texture fused after it would follow their errors (1 or more: never).
    pub registration_geometry_repeat_share: f64,
    /// A round on which fewer than this share of the frames converge has failed: its poses
    /// are discarded and the rounds stop. The video's drift fitted to the few frames that did
    /// converge would otherwise move all the others: from a real airway's tracker poses 3 mm /
    /// 4 deg off (ATM_224, 30 frames), the first geometry round converged on 4 frames, moved
    /// every frame about 4 mm, and the build ended 4.08 mm / 15.7 deg from the truth against
    /// 2.76 mm / 4.06 deg given (BENCHMARKS.md, session 24).
    pub registration_min_converged_share: f64,
    /// The refined poses are kept only when they predict held-out frames better than the given
    /// ones by more than this (dB). Each held-out frame's refined pose was registered against
    /// a texture it helped fuse, and a model fused at poses the registration made consistent
    /// predicts its own frames well even where those poses are off: from the exact poses of a
    /// real airway (ATM_224) the rounds moved them 0.26 mm / 0.58 deg and won the check by
    /// 0.36 dB while new views lost 3.8 dB. Poses 0.5 mm / 0.6 deg off lose the check by 4.1
    /// (ATM_224) and 6.0 dB (demo phantom), exact ones on the demo phantom win it by 0.6 dB
    /// (BENCHMARKS.md).
    pub registration_keep_margin_db: f64,
    /// Gain corrections of the light fitted in each registration round (the light's shape is
    /// not refitted there: the rounds only need a light to register against).
    pub registration_light_refinements: usize,
    /// Most samples pooled for the light of the registration's later geometry and shading
    /// rounds (the first geometry round's light, which also scores the given poses, its
    /// repeat's, and the light the refined poses are scored with pool `max_pooled_samples` like
    /// the build's).
    pub registration_light_samples: usize,
    /// The calibrated light of a model built with the same bronchoscope (`--scope-light`):
    /// the first registration round registers against its shape with this video's gains
    /// instead of a light fitted at the given poses, which follows their errors (a real
    /// airway, ATM_224, from tracker poses 3 mm / 4 deg off: the first round converged on 4 of
    /// 30 frames against that light, on 25 against the scope's; BENCHMARKS.md, session 25).
    pub scope_light: Option<ScopeLight>,
    /// Without a scope light, a first round that fails against the light fitted at the given
    /// poses is run again against a Lambertian lamp with a uniform beam and this video's gains
    /// (`shading::calibrated::lambert_lamp`), a light that needs no poses (ATM_224 from 3 mm /
    /// 4 deg: 4 of 30 frames converged against the fitted light, and the build kept the given
    /// poses; BENCHMARKS.md, session 26).
    pub registration_lambert_fallback: bool,
    /// A first round that still fails (against the scope light, or the fitted light and the
    /// lamp) is run again from the given poses corrected by the median correction of each
    /// frame's nearest frames, and again from where that run's frames agree, up to this many
    /// times (0: never): a tracker's drift is shared by neighbouring frames, and the median
    /// outvotes the frames that registered to the wrong place (ATM_224 from 4 mm / 5 deg and
    /// 5 mm / 6 deg: the given poses were kept; now 28 of 30 frames within 1 mm and 1 deg;
    /// from 6 mm / 7 deg, 9 runs to settle; BENCHMARKS.md, session 27).
    pub registration_consensus_passes: usize,
    /// Frames far less sharp than the model predicts them from their poses (motion blur,
    /// defocus) are left out of the model (`super::blur_check`), and the tracker does not
    /// accept them (`TrackOptions::blurred_below`; `--keep-blurred` keeps them).
    pub leave_out_blurred: bool,
    /// Tracking from the first pose (`--poses first`).
    pub tracking: super::tracking::TrackingOptions,
    /// The registration stops when a round moves the median pose less than this (mm) and less
    /// than 0.1 degree.
    pub registration_tolerance_mm: f64,
    /// Reference views (a folder with views.json, camera.json and the images, like the
    /// phantom's truth/): the report then scores the new views against them (Fig. 4), and the
    /// poses against the true ones when it holds a poses.json (a folder with the true poses
    /// alone scores the poses only).
    pub truth: Option<std::path::PathBuf>,
    /// Replace an existing model folder.
    pub force: bool,
    /// No progress bars.
    pub quiet: bool,
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            segment: SegmentCommandOptions::default(),
            atlas: AtlasOptions::default(),
            samples: SampleOptions::default(),
            fit: FitOptions::default(),
            // The predicted-intensity-weighted average, not the paper's max-weight choice:
            // measured on the phantom's truth views (80 frames) it renders new views 1.6 dB
            // better with the calibrated light (31.5 vs 29.9 dB) and 0.9 dB better with Psi;
            // max-weight keeps sharper texture (albedo error 11.7% vs 12.5%, held-out frames
            // +0.25 dB). `--fusion max` selects the paper's method. Weights squared (inverse
            // variance for intensity errors of constant size), measured on the 80-frame demo
            // against exponent 1: albedo error 10.47% -> 9.88%, held-out frames +0.25 dB
            // (calibrated) and +0.38 dB (paper), truth views -0.10 dB.
            fusion: FusionOptions {
                method: FusionMethod::WeightedAverage {
                    weight_exponent: DEFAULT_WEIGHT_EXPONENT,
                },
                ..Default::default()
            },
            // Synthesised, not filled: on the demo (49.5% of the wall unseen) the unseen walls get
            // the truth's contrast (luminance std 0.0967 vs truth 0.0948; fill 0.0537) and vessel
            // spectrum (log10 RMS 0.10; fill 1.53), the seam stays under the seen texture's own
            // step at the border; new views 33.08 vs 33.10 dB, SSIM 0.9187 vs 0.9192; +1.7 s
            // (BENCHMARKS.md, "Walls the video never saw").
            unseen: SynthesisOptions::default(),
            shading: None,
            calibrated: CalibratedOptions::default(),
            calibrated_reference: None,
            pool: PoolOptions::default(),
            // The light has a few dozen parameters and a gain per frame: on the 80-frame demo
            // 100k, 200k, 400k and 1.6M pooled samples give the same new views (33.14, 33.09,
            // 33.10, 33.11 dB) and held-out frames (33.75 dB); the fit's time grows with them.
            max_pooled_samples: 400_000,
            chroma_refits: 2,
            refine_gains: 2,
            // The uniform term: gathered + uniform (`both`) scores better on the path-traced
            // Mitsuba case (new views 33.33 -> 37.46 dB) but the phantom's worst gain error rises
            // to 5.1% (tests/cli_render.rs, bound 5%), and the photometric registration still
            // predicts with the uniform term alone. BENCHMARKS.md, "Inter-reflection gathered
            // from the geometry".
            interreflection: InterreflectionMode::Uniform,
            gather_nodes: 40,
            gather_rays: 36,
            gather_visibility: false,
            // Demo (80 frames, 1.6M pooled samples): k = 1, 2, 3 -> light stage 70, 44, 33 s
            // (loaded machine), new views 33.17, 33.11, 33.02 dB, held-out 33.76, 33.74, 33.74.
            consensus_texel_factor: 2,
            refine_light: 2,
            cross_validate_every: 5,
            cross_validate_max_frames: 24,
            working_level: None,
            depth_cache_bytes: 1 << 30,
            selection: SelectionOptions {
                max_frames: DEFAULT_MAX_FRAMES,
                ..Default::default()
            },
            // Refined by default, kept only when the refined poses predict held-out frames
            // better than the given ones. Demo phantom (BENCHMARKS.md, "Registration"): with
            // 1.5 mm / 2 degrees of tracker error, new views 20.38 -> 27.17 dB; with exact
            // poses the given ones are kept (33.17 dB, unchanged); +48 s of build.
            poses: PosesMode::Refine,
            // Geometry, texture, texture, geometry, texture, texture (1.5 mm / 2 deg on the
            // demo phantom: 0.122 mm / 0.362 deg median, 79 of 80 frames within 1 mm and 1 deg;
            // five rounds 0.160 mm / 0.376 deg, 75; three 0.144 mm / 0.685 deg, 76). A geometry
            // round brings back a shared pitch / yaw of about 0.25 deg that the two texture
            // rounds after it take away (BENCHMARKS.md); the sixth costs 4 s of the demo.
            // G T T G T T S T T: the last three rounds took the demo phantom with 1.5 mm /
            // 2 deg drift from 0.143 mm / 0.443 deg to 0.100 mm / 0.339 deg median, new views
            // 30.64 -> 31.07 dB, for a third more registration time (BENCHMARKS.md).
            registration_rounds: 9,
            registration_geometry_every: 3,
            registration_shading_from: 6,
            registration_joint: true,
            // From tracker poses 3 mm / 4 deg off, the demo phantom's first geometry round
            // leaves 37 of 80 frames outliers, a second one 8; from 1.5 mm / 2 deg 10, and a
            // second round there was no better (BENCHMARKS.md, issue 16, session 12). A real
            // airway (ATM_224) from 4 mm / 5 deg with a scope light: 7 of 30, and the round
            // repeated 0.099 mm / 0.402 deg, 29/30 frames, against 0.186 mm / 0.804 deg, 18/30
            // without (BENCHMARKS.md, session 25).
            registration_geometry_repeat_share: 0.2,
            registration_min_converged_share: 0.25,
            leave_out_blurred: true,
            registration_keep_margin_db: 1.0,
            registration_tolerance_mm: 0.05,
            registration_light_refinements: 0,
            // The light has a few dozen parameters and a gain per frame: 1250 samples per frame
            // of the demo's 80 fit it as well for the rounds once their poses are consistent
            // (1.5 mm / 2 deg: 30.97 -> 30.92 dB, 0.399 -> 0.317 deg median) in a third of the
            // time.
            registration_light_samples: 100_000,
            scope_light: None,
            registration_lambert_fallback: true,
            registration_consensus_passes: 10,
            tracking: Default::default(),
            truth: None,
            force: false,
            quiet: false,
        }
    }
}

/// What the build does with the case's poses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PosesMode {
    /// Refine every frame's pose against the CT (photometric registration), then build with
    /// the refined poses when they predict held-out frames better than the given ones.
    #[default]
    Refine,
    /// Trust the given poses.
    Fixed,
    /// Trust only the first frame's pose (a video without a tracker; poses.json may hold
    /// that pose alone): track the others frame by frame from it against the CT
    /// (`registration::track`), then refine them like [`PosesMode::Refine`].
    First,
}
