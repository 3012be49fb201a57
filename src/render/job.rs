//! A render checkpointed to a store job (`render --db PATH --job NAME`):
//! what identifies the job (its scene, with the files a glTF references,
//! and its settings), what a resume may skip and restore, and the one
//! store batch that commits each rendered frame.

use super::{FrameSettings, MethodSettings, Renderer, SceneSource};
use crate::film::{self, Film};
use crate::method::{FrameRecords, FrameStats};
use crate::scene::gltf_loader;
use crate::store::{
    schema::FrameSourcesValue, schema::JobValue, FrameCommit, JobSpec, RecordCommit, StateCommit,
    Store,
};
use anyhow::{bail, Context, Result};
use std::collections::BTreeSet;
use std::ops::Range;
use std::path::Path;

/// A store job a render checkpoints to (`render --db PATH --job NAME`).
pub struct StoreJob<'a> {
    pub store: &'a Store,
    pub job: JobValue,
}

/// What a scene source is, as a job records it: its text and content hash.
/// A built-in scene hashes as `builtin:NAME`; a file as the FNV-1a 64 of its
/// bytes, followed by `+` and the hash of the external files it references
/// (the `uri`s of glTF `buffers` and `images` other than `data:` URIs, in
/// file order, each with its URI) when it references any, so that editing a
/// `.bin` or a texture next to a `.gltf` changes the hash too.
pub fn scene_identity(source: &SceneSource) -> Result<(String, String)> {
    scene_identity_confined(source, None)
}

/// [`scene_identity`], the external files read only inside `root` when it
/// is given, as [`SceneSource::load_confined`] reads them (a URI that leads
/// out is an error naming it).
pub fn scene_identity_confined(
    source: &SceneSource,
    root: Option<&Path>,
) -> Result<(String, String)> {
    let hash = match source {
        SceneSource::Builtin(_) => crate::hash::content_hash(source.to_string().as_bytes()),
        SceneSource::File(path) => {
            let cannot_read =
                |e: String| anyhow::anyhow!("cannot read scene {}: {e}", path.display());
            let file = match root {
                None => path.clone(),
                Some(root) => gltf_loader::confined_file(path, root).ok_or_else(|| {
                    cannot_read("not inside the directory it is confined to".to_string())
                })?,
            };
            let bytes = gltf_loader::read_regular_file(&file, None).map_err(cannot_read)?;
            let main = crate::hash::content_hash(&bytes);
            let uris = external_uris(&bytes);
            if uris.is_empty() {
                main
            } else {
                let dir = path.parent().unwrap_or(Path::new("."));
                // The FNV-1a of every file's URI, length and bytes one
                // after the other, fed as each is read: memory for one
                // file at a time, however many URIs name a large one.
                let mut all = crate::hash::Fnv1a::default();
                for (uri, declared) in uris {
                    let cannot = |what: String| {
                        anyhow::anyhow!("{what} (referenced by scene {})", path.display())
                    };
                    let file = gltf_loader::confined_uri_file(dir, &uri, root).map_err(cannot)?;
                    let content = gltf_loader::read_regular_file(&file, declared)
                        .map_err(|e| cannot(format!("cannot read {}: {e}", file.display())))?;
                    all.write(uri.as_bytes());
                    all.write(&[0]);
                    all.write(&(content.len() as u64).to_le_bytes());
                    all.write(&content);
                }
                format!("{main}+{:016x}", all.finish())
            }
        }
    };
    Ok((source.to_string(), hash))
}

/// The external file URIs of a glTF (`.gltf` JSON, or the JSON chunk of a
/// `.glb`): `buffers[].uri` then `images[].uri`, `data:` URIs left out,
/// each with the length the loader reads of it (a buffer's `byteLength`:
/// a 12-byte buffer naming a huge file is not read whole here either).
/// Anything unreadable gives none (the scene loader reports it).
fn external_uris(bytes: &[u8]) -> Vec<(String, Option<u64>)> {
    let Some(json) = gltf_loader::json_chunk(bytes) else {
        return Vec::new();
    };
    let Ok(doc) = serde_json::from_slice::<serde_json::Value>(json) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for list in ["buffers", "images"] {
        for item in doc[list].as_array().into_iter().flatten() {
            if let Some(uri) = item["uri"].as_str() {
                if !uri.starts_with("data:") {
                    out.push((uri.to_string(), item["byteLength"].as_u64()));
                }
            }
        }
    }
    out
}

/// The job description of a render: compared with the stored job so that a
/// resume never mixes frames of different scenes or settings.
pub fn job_spec(
    name: &str,
    source: &SceneSource,
    method: &MethodSettings,
    settings: &FrameSettings,
    frames: Range<u32>,
) -> Result<JobSpec> {
    job_spec_confined(name, source, None, method, settings, frames)
}

/// [`job_spec`], the scene's external files hashed only inside `root` when
/// it is given ([`scene_identity_confined`]).
pub fn job_spec_confined(
    name: &str,
    source: &SceneSource,
    root: Option<&Path>,
    method: &MethodSettings,
    settings: &FrameSettings,
    frames: Range<u32>,
) -> Result<JobSpec> {
    let identity = scene_identity_confined(source, root)?;
    job_spec_of(name, identity, method, settings, frames)
}

/// [`job_spec`] of a scene whose identity ([`scene_identity`]) is known.
pub fn job_spec_of(
    name: &str,
    (scene, scene_hash): (String, String),
    method: &MethodSettings,
    settings: &FrameSettings,
    frames: Range<u32>,
) -> Result<JobSpec> {
    Ok(JobSpec {
        name: name.to_string(),
        scene,
        scene_hash,
        method: method.name().to_string(),
        settings: serde_json::to_string(method)
            .context("cannot write the method settings as JSON")?,
        width: settings.width,
        height: settings.height,
        spp: method.spp(),
        fps: settings.fps,
        seed: settings.seed,
        same_pattern: settings.same_pattern,
        frame_start: frames.start,
        frame_end: frames.end,
    })
}

/// The frames of `frames` that job `j` has done and that need not be
/// rendered again, their files written back to `out_dir`. A method that
/// carries state from frame to frame resumes after the longest finished
/// prefix whose state the store holds, and renders the rest again; without
/// such a state it starts the range over.
pub(super) fn resume(
    renderer: &mut Renderer,
    j: &StoreJob,
    frames: &Range<u32>,
    out_dir: &Path,
) -> Result<BTreeSet<u32>> {
    let mut done: BTreeSet<u32> = j
        .store
        .frames_done(j.job.id)?
        .into_iter()
        .filter(|frame| frames.contains(frame))
        .collect();
    if renderer.carries_state() {
        let finished = done.len();
        let prefix = frames.clone().take_while(|f| done.contains(f)).count() as u32;
        let looks_ahead = renderer.looks_ahead();
        if prefix as usize == frames.len() && rendered_as_one_chain(j, frames, looks_ahead)? {
            // Every frame done by this range's chain: nothing to render.
        } else if let Some((state, resumed)) = resumable_state(j, frames, prefix, looks_ahead)? {
            renderer
                .restore_state(state)
                .map_err(|e| j.store.state_error(j.job.id, e))?;
            done.retain(|&f| f < frames.start + resumed);
        } else {
            j.store.clear_state(j.job.id)?;
            done.clear();
        }
        if done.len() < finished {
            eprintln!(
                "warning: job {:?}: {} finished frames of {}..{} are rendered again (and replaced): \
                 `{}` carries its cache from frame to frame, from the first of the range it \
                 renders, and they were rendered by another range or lie past frames still to render",
                j.job.spec.name,
                finished - done.len(),
                frames.start,
                frames.end,
                renderer.method_name(),
            );
        }
    }
    for &frame in &done {
        restore_frame_files(j, frame, out_dir)?;
    }
    Ok(done)
}

/// Commits rendered `frame` to job `j` in one batch: its EXR, statistics,
/// the records the method `kept` with their samples, and its state changes.
pub(super) fn store_frame(
    renderer: &Renderer,
    j: &mut StoreJob,
    film: &Film,
    frame: u32,
    stats: &FrameStats,
    kept: Option<FrameRecords>,
    // The first frame of the render's chain of frames and, for a method
    // that looks ahead, its end: what the stored state is valid for.
    (chain_start, chain_end): (u32, Option<u32>),
) -> Result<()> {
    let exr = film::encode_exr(film)
        .map_err(|e| anyhow::anyhow!("cannot encode frame {frame} as EXR: {e}"))?;
    let mut kept = kept.unwrap_or_default();
    let mut samples = std::mem::take(&mut kept.samples).into_iter();
    let records = kept
        .records
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let block = samples.next().unwrap_or_default();
            let mut c = RecordCommit::from_record(r, block, kept.strata, frame);
            if let Some(&last) = kept.last_frames.get(i) {
                c.record.last_frame = last;
            }
            c
        })
        .collect();
    if renderer.carries_state() && kept.state.is_none() {
        bail!(
            "method {} carries state but reported no state changes for frame {frame}",
            renderer.method_name()
        );
    }
    let sources = FrameSourcesValue::of(&kept.records);
    let commit = FrameCommit {
        frame,
        width: film.width,
        height: film.height,
        exr: &exr,
        records,
        stats,
        state: kept.state.as_ref().map(|changes| StateCommit {
            chain_start,
            chain_end,
            changes,
        }),
        movies: kept.movies.as_ref(),
        sources: sources.as_ref(),
    };
    j.store.commit_frame(&mut j.job, commit)?;
    Ok(())
}

/// Whether every frame of `frames` (all done) was rendered by the chain a
/// render of `frames` makes: started at its first frame (and, for a method
/// that looks ahead, ending at its end), and still the latest chain at
/// its last frame. A chain renders its frames in order from its start, and
/// another chain writing any of them would have become the latest, so the
/// latest state says it for all. Done frames of other chains (a job
/// rendered as 0..3 and then 3..6, asked for 0..6) are rendered again.
fn rendered_as_one_chain(job: &StoreJob, frames: &Range<u32>, looks_ahead: bool) -> Result<bool> {
    let Some(head) = job.store.state_head(job.job.id)? else {
        return Ok(false);
    };
    Ok(head.chain_start == frames.start
        && head.chain_end == looks_ahead.then_some(frames.end)
        && head.frame + 1 >= frames.end)
}

/// The stored state to continue a stateful method within the finished
/// `prefix` of `frames`, and how many of its frames that state covers, if
/// the job holds the state of one of them from this range's chain. A chain
/// commits its frames in order, so every frame of the range up to its
/// head is the chain's own; the finished frames after the head (a range
/// rendered again over another chain's frames, stopped part way) are the
/// other chain's, and are rendered again.
fn resumable_state(
    job: &StoreJob,
    frames: &Range<u32>,
    prefix: u32,
    looks_ahead: bool,
) -> Result<Option<(crate::method::MethodState, u32)>> {
    let Some(head) = job.store.state_head(job.job.id)? else {
        return Ok(None);
    };
    let same_chain = head.chain_start == frames.start
        && head.chain_end == looks_ahead.then_some(frames.end)
        && (frames.start..frames.start + prefix).contains(&head.frame);
    if !same_chain {
        return Ok(None);
    }
    let covered = head.frame + 1 - frames.start;
    Ok(job.store.load_state(job.job.id)?.map(|s| (s, covered)))
}

/// Writes a finished frame's files from the store if `out_dir` lacks its
/// EXR or its PNG (a crash between the store's flush and the file write,
/// another `--out`, a file deleted).
fn restore_frame_files(job: &StoreJob, frame: u32, out_dir: &Path) -> Result<()> {
    let exr_path = film::frame_path(out_dir, frame, "exr");
    if exr_path.exists() && film::frame_path(out_dir, frame, "png").exists() {
        return Ok(());
    }
    let Some(bytes) = job.store.frame_exr(job.job.id, frame)? else {
        return Ok(());
    };
    // PNG first, EXR last (renamed into place): as `film::write_frame`, the
    // EXR's presence means the frame's files are complete.
    let temp = out_dir.join(format!(
        ".frame_{frame:04}.exr.restore-{}",
        std::process::id()
    ));
    let film = film::decode_exr(&bytes).with_context(|| {
        format!(
            "store {}: the stored EXR of frame {frame} of job {:?} is damaged \
             (`--force` renders the job again)",
            job.store.path().display(),
            job.job.spec.name
        )
    })?;
    std::fs::write(&temp, &bytes)
        .and_then(|()| std::fs::File::open(&temp)?.sync_all())
        .with_context(|| format!("cannot write {}", temp.display()))?;
    film::write_png(&film, &film::frame_path(out_dir, frame, "png"))?;
    std::fs::rename(&temp, &exr_path)
        .with_context(|| format!("cannot write {}", exr_path.display()))?;
    Ok(())
}
