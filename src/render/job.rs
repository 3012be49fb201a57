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
/// `.bin` or a texture next to a `.gltf` changes the hash too. The files
/// are hashed a chunk at a time (a huge image is never held); an image not
/// there, or not readable as a regular file, is hashed as such (the
/// renderer ignores images, so the job renders, and the image appearing
/// later changes the hash), a buffer not there is an error (the loader
/// needs it): see `hash_reference`.
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
                // after the other, fed a chunk at a time as each is read:
                // memory for one chunk, however large the files.
                let mut all = crate::hash::Fnv1a::default();
                for (uri, kind) in uris {
                    hash_reference(&mut all, dir, &uri, kind, root, path).map_err(|e| {
                        anyhow::anyhow!("{e} (referenced by scene {})", path.display())
                    })?;
                }
                format!("{main}+{:016x}", all.finish())
            }
        }
    };
    Ok((source.to_string(), hash))
}

/// What the hash of a scene's external files holds for an image that is
/// not there, after its URI and NUL: a length no file has (`u64::MAX`),
/// then `missing`.
const MISSING: &[u8] = b"\xff\xff\xff\xff\xff\xff\xff\xffmissing";

/// What it holds for an image that cannot be read as a regular file, after
/// its URI and NUL: as [`MISSING`], then `unreadable: ` and why.
const UNREADABLE: &[u8] = b"\xff\xff\xff\xff\xff\xff\xff\xffunreadable: ";

/// Feeds the external file that `uri` (of `scene`, in `dir`) names to
/// `all` ([`hash_external_file`]). The renderer ignores images: one that
/// is missing ([`MISSING`]), or that cannot be read as a regular file (a
/// URI of another scheme or with a malformed escape, a FIFO, a device, a
/// directory, a read error: [`UNREADABLE`], with a warning) is hashed as
/// such, so that the job renders as the scene does without `--job`, and
/// one whose image appears or changes later is another scene. The loader
/// needs its buffers: for them each is an error. So is an image outside
/// the directory a load is confined to (nothing outside is looked at).
fn hash_reference(
    all: &mut crate::hash::Fnv1a,
    dir: &Path,
    uri: &str,
    kind: External,
    root: Option<&Path>,
    scene: &Path,
) -> Result<(), String> {
    let image = kind == External::Image;
    let unreadable = |all: &mut crate::hash::Fnv1a, why: &str| {
        eprintln!(
            "warning: {}: image '{uri}' cannot be read ({why}); as the renderer ignores \
             images, the job's scene hash records it as unreadable",
            scene.display()
        );
        all.write(uri.as_bytes());
        all.write(&[0]);
        all.write(UNREADABLE);
        all.write(why.as_bytes());
    };
    if let (true, Err(why)) = (image, gltf_loader::uri_file(dir, uri)) {
        unreadable(all, &why);
        return Ok(());
    }
    let file = gltf_loader::confined_uri_file(dir, uri, root)?;
    // What a file that fails part way fed is taken back.
    let before = *all;
    match hash_external_file(all, uri, &file, kind.limit()) {
        Ok(true) => {}
        Ok(false) if image => all.write(MISSING),
        Ok(false) => return Err(format!("cannot read {}: file not found", file.display())),
        Err(why) if image => {
            *all = before;
            unreadable(all, &why);
        }
        Err(e) => return Err(format!("cannot read {}: {e}", file.display())),
    }
    Ok(())
}

/// Feeds `uri`, NUL, the length (u64 LE) and the bytes of `file` (at most
/// `limit` of them) to `hash`, the bytes a chunk at a time, never the
/// whole file in memory: the same hash as of all of them in one piece, as
/// earlier builds hashed them. `Ok(false)`, and only `uri` and NUL fed,
/// when there is no file; a FIFO or a device is refused, as
/// [`gltf_loader::read_regular_file`] refuses it.
fn hash_external_file(
    hash: &mut crate::hash::Fnv1a,
    uri: &str,
    file: &Path,
    limit: Option<u64>,
) -> Result<bool, String> {
    use std::io::Read;
    let opened = gltf_loader::open_regular_file(file, limit)?;
    hash.write(uri.as_bytes());
    hash.write(&[0]);
    let Some((mut reader, len)) = opened else {
        return Ok(false);
    };
    hash.write(&len.to_le_bytes());
    let mut chunk = vec![0u8; 1 << 16];
    let mut read = 0u64;
    loop {
        match reader.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => {
                hash.write(&chunk[..n]);
                read += n as u64;
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(format!("cannot read file: {e}")),
        }
    }
    if read != len {
        return Err(format!(
            "the file changed while it was read ({read} bytes of the {len} it held)"
        ));
    }
    Ok(true)
}

/// An external file of a glTF, as its scene's hash reads it.
#[derive(Clone, Copy, Debug, PartialEq)]
enum External {
    /// A buffer, of the length the loader reads of it (its `byteLength`).
    Buffer { byte_length: Option<u64> },
    /// An image, which the renderer ignores (it may be missing).
    Image,
}

impl External {
    /// How much of the file is the scene's: of a buffer, what the loader
    /// reads (a 12-byte buffer naming a huge file is not read whole).
    fn limit(self) -> Option<u64> {
        match self {
            External::Buffer { byte_length } => byte_length,
            External::Image => None,
        }
    }
}

/// The external file URIs of a glTF (`.gltf` JSON, or the JSON chunk of a
/// `.glb`): `buffers[].uri` then `images[].uri`, `data:` URIs left out,
/// each with what it is (a buffer's with its `byteLength`).
/// Anything unreadable gives none (the scene loader reports it).
fn external_uris(bytes: &[u8]) -> Vec<(String, External)> {
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
                    let kind = match list {
                        "buffers" => External::Buffer {
                            byte_length: item["byteLength"].as_u64(),
                        },
                        _ => External::Image,
                    };
                    out.push((uri.to_string(), kind));
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
        } else if let Some((mut state, resumed)) = resumable_state(j, frames, prefix, looks_ahead)?
        {
            if renderer.state_refers_to_record_samples() {
                state.record_samples = j.store.frame_record_samples(j.job.id, state.frame)?;
            }
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
                "warning: job {:?}: {} of the {finished} finished frames of {}..{} are rendered \
                 again (and replaced), {} skipped: `{}` carries its cache from frame to frame, \
                 from the first of the range it renders, and they were rendered by another range \
                 or lie past frames still to render",
                j.job.spec.name,
                finished - done.len(),
                frames.start,
                frames.end,
                done.len(),
                renderer.method_name(),
            );
        }
    }
    for &frame in &done {
        restore_frame_files(j, frame, out_dir)?;
    }
    Ok(done)
}

/// Commits rendered `frame` to job `j` in one batch: its EXR (`exr`,
/// [`film::encode_exr`] of `film`), statistics, the records the method
/// `kept` with their samples, and its state changes, which a method that
/// carries state (`stateful_method`, its name) must have kept.
pub(super) fn store_frame(
    j: &mut StoreJob,
    (film, exr): (&Film, &[u8]),
    frame: u32,
    stats: &FrameStats,
    kept: Option<FrameRecords>,
    // The first frame of the render's chain of frames and, for a method
    // that looks ahead, its end: what the stored state is valid for.
    (chain_start, chain_end): (u32, Option<u32>),
    stateful_method: Option<&str>,
) -> Result<()> {
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
    if let (Some(method), None) = (stateful_method, &kept.state) {
        bail!("method {method} carries state but reported no state changes for frame {frame}");
    }
    let sources = FrameSourcesValue::of(&kept.records);
    let commit = FrameCommit {
        frame,
        width: film.width,
        height: film.height,
        exr,
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
    let film = film::decode_exr(&bytes).with_context(|| {
        format!(
            "store {}: the stored EXR of frame {frame} of job {:?} is damaged \
             (`--force` renders the job again)",
            job.store.path().display(),
            job.job.spec.name
        )
    })?;
    // PNG first, the stored EXR bytes last (renamed into place), as a
    // render writes them.
    film::write_encoded_frame(&film, &bytes, out_dir, frame)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The hash of an external file as earlier builds computed it: the whole
    /// file (at most `limit` bytes) read into memory, then its URI, NUL,
    /// length and bytes hashed in one piece.
    fn whole_buffer_hash(uri: &str, file: &Path, limit: Option<u64>) -> u64 {
        let content = gltf_loader::read_regular_file(file, limit).unwrap();
        let mut h = crate::hash::Fnv1a::default();
        h.write(uri.as_bytes());
        h.write(&[0]);
        h.write(&(content.len() as u64).to_le_bytes());
        h.write(&content);
        h.finish()
    }

    /// Streamed a chunk at a time, a file hashes as it did whole (several
    /// chunks and a part, an empty file, a limit inside the file and past
    /// it), so that stored jobs still resume; a missing file feeds only its
    /// URI and NUL, and a FIFO is refused without blocking.
    #[test]
    fn a_streamed_file_hashes_as_the_whole_buffer_did() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("tex.png");
        let bytes: Vec<u8> = (0..(3 << 16) + 1234u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
            .collect();
        for content in [&bytes[..], &[][..], &b"png"[..]] {
            std::fs::write(&file, content).unwrap();
            for limit in [None, Some(0), Some(70_000), Some(1 << 30)] {
                let mut streamed = crate::hash::Fnv1a::default();
                assert!(hash_external_file(&mut streamed, "tex.png", &file, limit).unwrap());
                assert_eq!(
                    streamed.finish(),
                    whole_buffer_hash("tex.png", &file, limit),
                    "{} bytes, limit {limit:?}",
                    content.len()
                );
            }
        }
        let mut missing = crate::hash::Fnv1a::default();
        let none = dir.path().join("none.png");
        assert!(!hash_external_file(&mut missing, "none.png", &none, None).unwrap());
        assert_eq!(missing.finish(), crate::hash::fnv1a(b"none.png\0"));
        let fifo = dir.path().join("fifo.png");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let mut h = crate::hash::Fnv1a::default();
            let err = hash_external_file(&mut h, "fifo.png", &fifo, None).unwrap_err();
            assert_eq!(err, "not a regular file (it is a FIFO)");
        }
    }

    /// A scene whose image is missing hashes (the renderer ignores images)
    /// as another than with the image there; one whose buffer is missing is
    /// an error naming the file and the scene.
    #[test]
    fn a_missing_image_is_hashed_as_missing_and_a_missing_buffer_refused() {
        let dir = tempfile::tempdir().unwrap();
        let gltf = dir.path().join("s.gltf");
        std::fs::write(
            &gltf,
            br#"{"asset":{"version":"2.0"},"buffers":[{"uri":"b.bin","byteLength":4}],"images":[{"uri":"t.png"}]}"#,
        )
        .unwrap();
        std::fs::write(dir.path().join("b.bin"), [1u8, 2, 3, 4]).unwrap();
        let source = SceneSource::File(gltf.clone());
        let (_, without) = scene_identity(&source).unwrap();
        assert_eq!(scene_identity(&source).unwrap().1, without, "stable");
        std::fs::write(dir.path().join("t.png"), b"").unwrap();
        let (_, with) = scene_identity(&source).unwrap();
        assert_ne!(with, without, "an image that appears changes the hash");
        std::fs::remove_file(dir.path().join("b.bin")).unwrap();
        let msg = scene_identity(&source).unwrap_err().to_string();
        assert!(
            msg.contains("b.bin: file not found") && msg.contains("s.gltf"),
            "{msg}"
        );
    }

    /// An image that cannot be read as a regular file (a URI of another
    /// scheme or with a malformed escape, a directory, a FIFO) is hashed
    /// as unreadable, as a missing one is hashed as missing: the job
    /// renders as the scene does without `--job` (the renderer ignores
    /// images; the job was refused). The hash is stable, and changes when
    /// the image becomes readable. A buffer that cannot be read is still
    /// an error naming it and the scene.
    #[test]
    fn an_unreadable_image_is_hashed_as_such_and_an_unreadable_buffer_refused() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("b.bin"), [1u8, 2, 3, 4]).unwrap();
        std::fs::create_dir(dir.path().join("sub.png")).unwrap();
        let fifo = dir.path().join("fifo.png");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        let gltf = dir.path().join("s.gltf");
        let scene = |buffer: &str, image: &str| {
            let doc = serde_json::json!({"asset": {"version": "2.0"},
                "buffers": [{"uri": buffer, "byteLength": 4}], "images": [{"uri": image}]});
            std::fs::write(&gltf, serde_json::to_vec(&doc).unwrap()).unwrap();
            scene_identity(&SceneSource::File(gltf.clone()))
        };
        let mut images = vec!["http://example.com/t.png", "%zz.png", "sub.png"];
        if made.is_ok_and(|s| s.success()) {
            images.push("fifo.png");
        }
        for image in images {
            let (_, hash) = scene("b.bin", image).unwrap_or_else(|e| panic!("{image}: {e}"));
            assert_eq!(scene("b.bin", image).unwrap().1, hash, "{image}: stable");
        }
        let (_, unreadable) = scene("b.bin", "sub.png").unwrap();
        std::fs::remove_dir(dir.path().join("sub.png")).unwrap();
        std::fs::write(dir.path().join("sub.png"), b"").unwrap();
        let (_, readable) = scene("b.bin", "sub.png").unwrap();
        assert_ne!(readable, unreadable);
        let msg = scene("http://example.com/b.bin", "t.png")
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("only files are read, not 'http:' URIs") && msg.contains("s.gltf"),
            "{msg}"
        );
        std::fs::create_dir(dir.path().join("dir.bin")).unwrap();
        let msg = scene("dir.bin", "t.png").unwrap_err().to_string();
        assert!(
            msg.contains("dir.bin: not a regular file (it is a directory)")
                && msg.contains("s.gltf"),
            "{msg}"
        );
    }
}
