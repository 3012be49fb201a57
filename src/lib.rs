//! radcache: a renderer for animated scenes with global illumination that
//! reuses lighting work across frames.
//!
//! The crate is laid out one module per concept (see `DESIGN.md` in the
//! shared design folder for the full picture):
//!
//! | module      | owns                                                          |
//! |-------------|---------------------------------------------------------------|
//! | [`scene`]   | scene description, glTF loading, built-in scenes, animation   |
//! | [`accel`]   | BVHs over the triangles of one frame (obvhs)                   |
//! | [`backend`] | the batched ray interface; its CPU and wgpu (GPU) implementations |
//! | [`cache`]   | irradiance records, gathering, gradients, interpolation      |
//! | [`sampling`]| deterministic random numbers keyed by (seed, frame, pixel, sample) |
//! | [`material`]| BSDFs: Lambertian and energy-conserving modified Phong         |
//! | [`light`]   | light sampling: emissive triangles by power, point and spot   |
//! | [`method`]  | rendering methods behind one trait (`path`, `ic`, `trc`, `tcg`, `movies`) |
//! | [`integrator`] | path tracing of ray batches, shared by all methods        |
//! | [`film`]    | RGB f32 images, EXR and PNG input/output                        |
//! | [`hash`]    | FNV-1a 64, the content hash of scenes and their files          |
//! | [`metrics`] | RMSE, relative RMSE, block bias and flicker, error maps; `compare` |
//! | [`render`]  | the frame loop: animation → geometry → method → files         |
//! | [`bench`](mod@bench) | `radcache bench`: methods against a reference, CSV and charts |
//! | [`cli`]     | the `radcache` command line                                    |
//! | [`server`]  | `radcache serve`: the HTTP API (axum) and its job worker        |
//! | [`store`]   | the persistent space-time store (sled + rkyv + zstd), jobs, resume |
//! | [`decimal`] | numbers in names read back only in the spelling they are written |
//! | [`uri`]     | percent-encoding of glTF URIs and query strings                |
//! | [`regular_file`] | opening files that must be regular ones (not a FIFO or a device) |
//! | [`system_memory`] | the memory this process may still take (/proc, cgroups, `ulimit -v`) |

pub mod accel;
pub mod backend;
pub mod bench;
pub mod cache;
pub mod cli;
pub mod decimal;
pub mod film;
pub mod hash;
pub mod integrator;
pub mod light;
pub mod material;
pub mod method;
pub mod metrics;
pub mod regular_file;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod server;
pub mod store;
pub mod system_memory;
pub mod uri;
