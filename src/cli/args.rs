//! The command line's arguments: one clap struct per verb, their value
//! enums, and the parsers that turn a bad value into a clear clap error
//! (never a panic). A method setting's flag takes the range of its name
//! (`method::settings::limits`), so that every value a flag takes can be
//! posted back by name.

use crate::bench;
use crate::cache::gather::Strata;
// Number flags parse with their setting's range (`limits::X.parser()`:
// "expected a number from MIN to MAX" for any value refused) and allow
// negative numbers, so that clap hands `-1` to the parser rather than
// taking it for a flag.
use crate::method::settings::{limits, parse_strata};
use crate::render::{self, SceneSource};
use clap::{Args, ValueEnum};
use std::ops::Range;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct CompactArgs {
    /// Store directory.
    #[arg(long, default_value = DEFAULT_DB)]
    pub db: PathBuf,
    /// No progress bar (the summary is still printed).
    #[arg(long, short)]
    pub quiet: bool,
}

#[derive(Args, Debug)]
pub struct DeleteArgs {
    /// Store directory.
    #[arg(long, default_value = DEFAULT_DB)]
    pub db: PathBuf,
    /// Jobs to delete, by name (as `inspect` lists them). All must exist:
    /// a name that does not deletes none.
    #[arg(required = true, value_name = "JOB")]
    pub jobs: Vec<String>,
}

#[derive(Args, Debug)]
pub struct ServeArgs {
    /// Store directory.
    #[arg(long, default_value = DEFAULT_DB)]
    pub db: PathBuf,
    /// Address to listen on (non-loopback needs --token).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub addr: std::net::SocketAddr,
    /// Directory of scene files jobs may name (relative paths only).
    #[arg(long)]
    pub scenes: Option<PathBuf>,
    /// Token every request must carry (Authorization: Bearer TOKEN or ?token=).
    #[arg(long, env = "RADCACHE_TOKEN")]
    pub token: Option<String>,
    /// Ray backend.
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendArg,
    /// Directory of each job's frame files (DIR/JOB_ID/) [default: DB.frames].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// A `radcache bench --out DIR` directory whose charts (*.svg, *.csv)
    /// the dashboard shows [default: the charts kept in web/charts].
    #[arg(long)]
    pub bench: Option<PathBuf>,
    /// Seconds a client may take to send a request's head, and then its
    /// body (a slower one is disconnected, or answered 408), and, while an
    /// answer is written, to take some of it (else it is disconnected); an
    /// idle kept-alive connection is closed after as long.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true, value_parser = client_timeout)]
    pub client_timeout: f64,
    /// Connections one client address (an IPv4 address, an IPv6 /64) may
    /// hold open at once, of the server's 512; a reverse proxy on the same
    /// host is one address for all its clients.
    #[arg(long, default_value_t = crate::server::MAX_CONNECTIONS_PER_PEER,
          allow_negative_numbers = true, value_parser = connections_per_peer)]
    pub connections_per_peer: usize,
}

/// `--connections-per-peer`: 1 to 512 (the server's connections).
fn connections_per_peer(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n @ 1..=512) => Ok(n),
        _ => Err(format!(
            "`{s}` is not a number of connections from 1 to 512"
        )),
    }
}

/// `--client-timeout`: a number of seconds in [0.1, 86400].
fn client_timeout(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("`{s}` is not a number of seconds"))?;
    if (0.1..=86_400.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} s is outside 0.1 s to 86400 s"))
    }
}

/// Default store directory (DESIGN.md "The store"), used when `--job` is
/// given without `--db`, and by `inspect`.
pub const DEFAULT_DB: &str = "radcache.db";

#[derive(Args, Debug)]
pub struct InspectArgs {
    /// Only this job (default: every job).
    pub job: Option<String>,
    /// Store directory.
    #[arg(long, default_value = DEFAULT_DB)]
    pub db: PathBuf,
    /// Per-frame details of this frame only (default: every frame when a JOB is given).
    #[arg(long, allow_negative_numbers = true, value_parser = parse_frame_number)]
    pub frame: Option<u32>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Rendering methods available in this build.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MethodName {
    /// Unbiased path tracer (NEE + MIS + Russian roulette): the accuracy yardstick.
    Path,
    /// Per-frame irradiance caching (Ward 1988, Ward & Heckbert 1992): a new cache every frame.
    Ic,
    /// Temporal radiance caching (Gautron et al., TVCG 2007): ic records that live across frames.
    Trc,
    /// Temporally coherent final gathering (Tawara et al., 2004): records keep their samples and re-shoot a share of them each frame.
    Tcg,
    /// Texture movies with a coarse radiosity global pass (Martín, Pueyo & Tost, 2003): per visible triangle side a texture over time; static shadows found once per movie.
    Movies,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum BackendArg {
    Auto,
    Cpu,
    Gpu,
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// glTF 2.0 scene (.gltf or .glb). Without it, the built-in `cube-in-box`.
    pub scene: Option<PathBuf>,
    /// Built-in scene: cube-in-box, moving-light, spheres, glossy-cornell, chairs-room.
    #[arg(long, conflicts_with = "scene")]
    pub builtin: Option<String>,
    /// Rendering method: by default `trc`, the temporal method this
    /// renderer is built around (`path` is the unbiased yardstick).
    #[arg(long, value_enum, default_value = "trc")]
    pub method: MethodName,
    /// Half-open frame range START..END (0..24 is frames 0 to 23).
    #[arg(long, default_value = "0..24", allow_hyphen_values = true, value_parser = parse_frames)]
    pub frames: Range<u32>,
    /// Image size WxH.
    #[arg(long, default_value = "256x256", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Samples per pixel [default: 16; for ic the samples of direct light and anti-aliasing].
    #[arg(long, allow_negative_numbers = true, value_parser = limits::SPP.parser())]
    pub spp: Option<u32>,
    /// Frames per second: frame f is rendered at t = f / fps.
    #[arg(long, default_value_t = crate::scene::DEFAULT_FPS, allow_negative_numbers = true, value_parser = parse_fps)]
    pub fps: f32,
    /// Random seed; the same seed gives the same frames.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true, value_parser = parse_seed)]
    pub seed: u64,
    /// Use the same random sequence in every frame (reference sequences for the flicker figure).
    #[arg(long)]
    pub same_pattern: bool,
    /// Output directory.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Ray backend.
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendArg,
    /// Hard limit on path length in bounces, 0 to 10000 (default: unbounded, Russian roulette).
    #[arg(long, allow_negative_numbers = true, value_parser = limits::PATH_DEPTH.parser())]
    pub max_depth: Option<u32>,
    #[command(flatten)]
    pub ic: IcArgs,
    #[command(flatten)]
    pub trc: TrcArgs,
    #[command(flatten)]
    pub tcg: TcgArgs,
    #[command(flatten)]
    pub movies: MoviesArgs,
    /// Record the render as job NAME in the store and resume it if it was interrupted
    /// (frames already finished are skipped). The store is --db, default ./radcache.db.
    #[arg(long, value_name = "NAME", value_parser = parse_job_name)]
    pub job: Option<String>,
    /// Store directory for --job [default: ./radcache.db]. Only used with --job.
    #[arg(long, value_name = "PATH", requires = "job")]
    pub db: Option<PathBuf>,
    /// With --job: start the job over, dropping its stored frames: needed when its scene or settings changed (else an error), and the way out for a job whose stored frames are damaged.
    #[arg(long, requires = "job")]
    pub force: bool,
    /// Render even where the frame's estimated peak memory (a lower bound: what every pixel, sample and scene triangle takes) is over the memory available, which is otherwise refused before anything renders.
    #[arg(long)]
    pub no_memory_check: bool,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Settings of `--method ic`.
#[derive(Args, Debug)]
pub struct IcArgs {
    /// Accuracy a: records are used where their weight w ≥ 1/a (Ward 1988 recommends 0.1–0.3).
    #[arg(long, default_value_t = 0.2, allow_negative_numbers = true, value_parser = limits::ACCURACY.parser())]
    pub ic_accuracy: f32,
    /// Hemisphere cells per record, MxN (θ × φ; Ward & Heckbert 1992 use N ≈ πM), at most 65536.
    #[arg(long, default_value = "16x48", value_parser = parse_strata)]
    pub ic_strata: Strata,
    /// Smallest record spacing in pixels (screen-space clamp of the record radius).
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true, value_parser = limits::SPACING_PX.parser())]
    pub ic_min_spacing: f32,
    /// Largest record influence radius in pixels.
    #[arg(long, default_value_t = 64.0, allow_negative_numbers = true, value_parser = limits::SPACING_PX.parser())]
    pub ic_max_spacing: f32,
    /// Interpolate without the translation and rotation gradients.
    #[arg(long)]
    pub ic_no_gradients: bool,
    /// Indirect light of glossy lobes: path (traced from a lobe sample per pixel sample) or eas (radiance records of equivalent area light sources, Omidvar et al.; `ic`, `trc` and `tcg`).
    #[arg(long, value_enum, default_value = "path")]
    pub ic_glossy: GlossyArg,
    /// EAS precision criterion τ: a record's sources are refined until their reflected radiance is within τ of the finer level's (Eq. 13; the paper uses 0.02).
    #[arg(long, default_value_t = crate::cache::eas::DEFAULT_TAU, allow_negative_numbers = true, value_parser = limits::EAS_TAU.parser())]
    pub ic_eas_tau: f32,
}

/// Settings of `--method trc` (its spatial settings are the `--ic-*` ones).
#[derive(Args, Debug)]
pub struct TrcArgs {
    /// Temporal accuracy a_t: a record is used while w_t = 1/(|τ−1|(t−t0)) ≥ 1/a_t (TRC Eq. 9–10; the paper uses 0.05).
    #[arg(long, default_value_t = 0.05, allow_negative_numbers = true, value_parser = limits::TEMPORAL_ACCURACY.parser())]
    pub trc_at: f32,
    /// δt_max: longest life of a record in frames, t − t0 < δt_max (TRC Eq. 11; the paper uses 20 on Cube in a Box, 5 on Spheres).
    #[arg(long, default_value_t = 20, allow_negative_numbers = true, value_parser = limits::MAX_LIFE.parser())]
    pub trc_max_life: u32,
    /// Temporal gradients (TRC §4.5): none, extrapolated from the estimate of E(t0+1) (Eq. 15, E's change alone, one pass), or interpolated towards the record's replacement (Eq. 18–20, two passes: frames come out up to δt_max frames of first pass late).
    #[arg(long, value_enum, default_value = "extrapolated")]
    pub trc_gradients: TrcGradientsArg,
    /// Estimate E(t0+1) by reprojecting the record's hemisphere samples (TRC §4.7), and check the record's life by reprojecting them to the later frames whose motion departs from the extrapolated one (an object that starts, stops or jumps, a light switched off or moved), and against objects none of its samples hit that come into their paths (one that jumps in or grows from nothing); off: E constant, no check.
    #[arg(long, value_enum, default_value = "on")]
    pub trc_reprojection: OnOff,
    /// With reprojection, evaluate each hemisphere sample's direct light again at t0+1 (one light sample, shadowed in the next frame's geometry), so that E(t0+1) sees moving shadows and moving lights (TRC §5: the incoming lighting at t+1 of each visible point): moving-lights, at frames after which a light moves (a moving light moves the shadows of static objects too, which nothing else in the estimate sees); long-lives, there and also where only objects move at frames whose records live long (harmonic mean lifespan of the records alive ≥ δt_max/2: there each record's estimate decides many frames); on, at every frame (where records live short it costs up to 27 % more time for nothing; benches/RESULTS.md); off, never.
    #[arg(long, value_enum, default_value = "long-lives")]
    pub trc_next_direct: NextDirectArg,
    /// A replacement record takes the results of the paths of the record it replaces that nothing moving met, then or now, rather than tracing them again; where the lights moved, the hits of their extension rays, tracing only their shadow rays: the same records, faster (not in the paper, which traces them all again).
    #[arg(long, value_enum, default_value = "on")]
    pub trc_keep_paths: OnOff,
    /// A replacement record's estimate of E(t0+1) also follows the change observed over the life of the record it replaces (E of the replacement minus E of the record, a frame), where that change is the larger: the reprojection keeps each sample's radiance and misses light of more than one bounce that moving objects change, so records lived on while it drifted (not in the paper; off: its estimate alone).
    #[arg(long, value_enum, default_value = "on")]
    pub trc_history: OnOff,
}

/// Settings of `--method tcg` (its spatial settings are the `--ic-*` ones).
#[derive(Args, Debug)]
pub struct TcgArgs {
    /// τ_min of Eq. 2: the share of a record's samples shot again every frame (Tawara et al. 2004; their results use 0.05).
    #[arg(long, default_value_t = 0.05, allow_negative_numbers = true, value_parser = limits::SHARE.parser())]
    pub tcg_tau_min: f32,
    /// τ_max of Eq. 2: the share shot again of the samples that hit moving objects (their results use 1.0).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = limits::SHARE.parser())]
    pub tcg_tau_max: f32,
    /// §4.2: a record with more usable neighbours than this is removed as redundant (their example: 10).
    #[arg(long, default_value_t = 10, allow_negative_numbers = true, value_parser = limits::MAX_NEIGHBOURS.parser())]
    pub tcg_max_neighbours: u32,
    /// Samples whose light moving lights may have changed by more than 5 % since they were shot (on a surface of any normal at their hit, unshadowed), and their neighbours across an edge, are shot again as those that hit moving objects are (not in the paper, whose Eq. 2 counts only the latter; off, a moving light's indirect light lags by up to 1/τ_min frames).
    #[arg(long, value_enum, default_value = "on")]
    pub tcg_light_refresh: OnOff,
    /// Samples whose path an object moved into since the last frame (a ray-box test along their cell's centre) are shot again as those that hit moving objects are, and records a moved object buried are dropped (not in the paper). For objects that jump or appear: off, their indirect shadow comes in over some 1/τ_min frames; on, it costs 1.3× the time on cube-in-box and 1.6× on spheres (benches/RESULTS.md).
    #[arg(long, value_enum, default_value = "off")]
    pub tcg_occlusion_refresh: OnOff,
    /// A record whose samples' paths moving objects newly cross by more than 5 % in one frame is dropped, and made again where a pixel needs it: objects none of its samples hit, or that they hit and that came nearer (not in the paper, whose records learn of a moving object only through the samples that hit it). For objects that jump in, grow or slide into a record's view: off, their light and shadow come in over some 1/τ_min frames.
    #[arg(long, value_enum, default_value = "on")]
    pub tcg_arrivals: OnOff,
}

/// Settings of `--method movies`.
#[derive(Args, Debug)]
pub struct MoviesArgs {
    /// Shadow samples per texel: sample points on the lights (the paper's N, §3.1), at most 64.
    #[arg(long, default_value_t = 16, allow_negative_numbers = true, value_parser = limits::SHADOW_SAMPLES.parser())]
    pub movies_shadow_samples: u32,
    /// Texels across a pixel's footprint (§3.1: at least one texel covers one pixel), 0.01 to 16.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = limits::TEXELS_PER_PIXEL.parser())]
    pub movies_texels_per_pixel: f32,
    /// Finest texture, texels along a triangle's edge, at most 1024.
    #[arg(long, default_value_t = 256, allow_negative_numbers = true, value_parser = limits::MAX_RESOLUTION.parser())]
    pub movies_max_resolution: u32,
    /// Memory for the movies' kept static shadows, in MiB (past it the largest give theirs up and find them again).
    #[arg(long, default_value_t = 512, allow_negative_numbers = true, value_parser = limits::MEMORY_MIB.parser())]
    pub movies_memory_mib: u32,
    /// Global pass: grid spacing as a fraction of the static scene's diagonal (or of twice that of what the camera sees at time 0, where smaller), 0.001 to 1, at images up to 128 pixels high; a higher image is meshed finer in proportion to its height (half the spacing at 256x256).
    #[arg(long, default_value_t = 1.0 / 32.0, allow_negative_numbers = true, value_parser = limits::GRID_SPACING.parser())]
    pub movies_spacing: f32,
    /// Global pass: links (gather rays) of a vertex that stands for a spacing squared of surface, at most 1024; one that stands for less (as most grid vertices do: their cells are at most a spacing along their longest edge) gets fewer in proportion, about half as many on most grids; then twice that on triangles the camera sees (less where the pass's link budget has no room), half on those it does not.
    #[arg(long, default_value_t = 128, allow_negative_numbers = true, value_parser = limits::LINKS.parser())]
    pub movies_links: u32,
    /// Global pass: most bounces of indirect light (Jacobi iterations, at most 64; it stops sooner once they change it by under 0.1 %); the bounces after the last are added as a geometric series once their decay has settled.
    #[arg(long, default_value_t = 64, allow_negative_numbers = true, value_parser = limits::BOUNCES.parser())]
    pub movies_bounces: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum GlossyArg {
    Path,
    Eas,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TrcGradientsArg {
    None,
    Extrapolated,
    Interpolated,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum NextDirectArg {
    Off,
    MovingLights,
    LongLives,
    On,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum OnOff {
    On,
    Off,
}

#[derive(Args, Debug)]
pub struct CompareArgs {
    /// Directory of reference frames (frame_NNNN.exr).
    pub reference: PathBuf,
    /// Directory of frames to judge.
    pub test: PathBuf,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Also write DIR/error_NNNN.png for each frame: red where the test is
    /// brighter than the reference, blue where darker, in full colour from
    /// ±25 % of the reference pixel's luminance (pixels darker than 5 % of
    /// the frame's mean are judged against that), over the reference in grey;
    /// and DIR/error_mean.png, the same of the frames' means (their bias).
    #[arg(long, value_name = "DIR")]
    pub error_maps: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Comma-separated built-in scene names and/or .gltf/.glb files.
    #[arg(long, default_value = "cube-in-box", value_delimiter = ',', value_parser = parse_bench_scene)]
    pub scenes: Vec<SceneSource>,
    /// Methods, each NAME or NAME:KEY=V1,V2,… sweeping one setting (one run per value),
    /// with more :KEY=V settings fixed in every run, e.g.
    /// `--methods path:spp=4,16,64 ic:accuracy=0.1,0.2 trc:at=0.1:max_life=5,20`.
    #[arg(long, num_args = 1.., default_values = bench::DEFAULT_METHODS, value_parser = parse_bench_method)]
    pub methods: Vec<bench::MethodSweep>,
    /// Half-open frame range START..END.
    #[arg(long, default_value = "0..24", allow_hyphen_values = true, value_parser = parse_frames)]
    pub frames: Range<u32>,
    /// Image size WxH.
    #[arg(long, default_value = "64x64", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Samples per pixel of the converged path reference.
    #[arg(long, default_value_t = 1024, allow_negative_numbers = true,
          value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    pub reference_spp: u32,
    /// Frames per second: frame f is rendered at t = f / fps.
    #[arg(long, default_value_t = crate::scene::DEFAULT_FPS, allow_negative_numbers = true, value_parser = parse_fps)]
    pub fps: f32,
    /// Random seed of the runs; the reference's is derived from it, never
    /// equal to it, so that no run draws the reference's random numbers.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true, value_parser = parse_seed)]
    pub seed: u64,
    /// Output directory: bench.csv, charts, reference/ and runs/.
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
    /// Render the runs too with the same random sequence in every frame
    /// (the reference always is): flicker then shows what a method changes
    /// between frames rather than its per-frame pixel noise.
    #[arg(long)]
    pub same_pattern: bool,
    /// No progress bars or messages (the table is still printed).
    #[arg(long, short)]
    pub quiet: bool,
    /// For trc runs, also measure the error of the records' E(t0+1)
    /// estimate, with and without reprojection, over every record the run
    /// computes (TRC Table 1): a second, untimed pass gathers each record
    /// again one frame later.
    #[arg(long)]
    pub estimate_error: bool,
    /// Also render every run, untimed, into a store of its own
    /// (`runs/<scene>/<run>/store`, left for inspect) and report its bytes
    /// on disk (sled and sample log).
    #[arg(long)]
    pub store_size: bool,
    /// Ray backends, comma-separated: every run is rendered once on each
    /// (`cpu,gpu` compares them in one invocation; the reference uses auto).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "auto")]
    pub backends: Vec<BackendArg>,
    /// Time every run N times, in N rounds over all of a scene's runs (the
    /// machine's drift then falls on every run alike), and report each
    /// run's median time; frames, errors and records are the first
    /// round's (the later rounds render the same frames for their time
    /// alone). A Ctrl-C in a later round keeps the rounds done.
    #[arg(long, value_name = "N", default_value_t = 1,
          value_parser = clap::value_parser!(u32).range(1..=100))]
    pub repeat: u32,
    /// Render every run at N seeds (--seed, --seed + 1, …) against the
    /// one reference, and report the means of its errors and records over
    /// them (each seed's errors listed after the tables and in
    /// bench_seeds.csv, their range a bar on the charts; its time,
    /// rays and memory stay the first seed's). trc and tcg keep their pixel
    /// samples' streams from frame to frame, so one seed's error is one
    /// draw of their pixel noise.
    #[arg(long, value_name = "N", default_value_t = 1,
          value_parser = clap::value_parser!(u32).range(1..=64))]
    pub seeds: u32,
    /// Run even where a run's estimated peak memory at --size on its scene (a lower bound, as for `render`) is over the memory available, which is otherwise refused before anything renders.
    #[arg(long)]
    pub no_memory_check: bool,
    /// Render nothing: read --out's bench.csv (and bench_seeds.csv, if
    /// any), which an earlier bench wrote, print its tables and draw its
    /// charts into --out again (after the CSV was edited or merged, or the
    /// charts' drawing changed). Goes with --out and --quiet only.
    #[arg(long, conflicts_with_all = [
        "scenes", "methods", "frames", "size", "reference_spp", "fps", "seed",
        "same_pattern", "estimate_error", "store_size", "backends", "repeat",
        "seeds", "no_memory_check",
    ])]
    pub replot: bool,
}

fn parse_bench_scene(s: &str) -> Result<SceneSource, String> {
    bench::parse_scene(s).map_err(|e| e.to_string())
}

fn parse_bench_method(s: &str) -> Result<bench::MethodSweep, String> {
    bench::MethodSweep::parse(s).map_err(|e| e.to_string())
}

/// Largest image side accepted; beyond it a typo is likelier than intent.
const MAX_SIDE: u32 = 16384;

fn parse_frames(s: &str) -> Result<Range<u32>, String> {
    render::parse_frame_range(s)
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    render::parse_image_size(s, MAX_SIDE)
}

fn parse_job_name(s: &str) -> Result<String, String> {
    if s.is_empty() || s.len() > 200 || s.chars().any(|c| c.is_control()) {
        return Err(format!(
            "job name {s:?} must be 1 to 200 characters without control characters"
        ));
    }
    // `radcache serve` would take such a job in the same store for one of
    // its own, and queue it if unfinished.
    if crate::server::parse_job_id(s).is_some() {
        return Err(format!(
            "job name {s:?} has the form job-N, which radcache serve gives its own jobs; \
             pick another name"
        ));
    }
    Ok(s.to_string())
}

/// `--seed`: any whole number from 0 to 2⁶⁴ − 1.
fn parse_seed(s: &str) -> Result<u64, String> {
    s.trim()
        .parse()
        .map_err(|_| format!("expected a whole number from 0 to {}", u64::MAX))
}

/// `inspect --frame`: a frame number, 0 to 2³² − 1.
fn parse_frame_number(s: &str) -> Result<u32, String> {
    s.trim()
        .parse()
        .map_err(|_| format!("expected a frame number from 0 to {}", u32::MAX))
}

fn parse_fps(s: &str) -> Result<f32, String> {
    let fps: f32 = s.parse().map_err(|_| format!("'{s}' is not a number"))?;
    if !crate::render::FPS_RANGE.contains(&fps) {
        return Err(format!("fps must lie in 0.001..=100000, got {s}"));
    }
    Ok(fps)
}
