//! A model swapped in during a run (`formation swap`), as a recording keeps it: the model file is
//! stored as an attachment when it is not a shipped one, and one metadata record per swap maps the
//! model id the replay steps name to where its bytes are.
//!
//! The record ([`SWAP_METADATA`], format [`SWAP_FORMAT`] v[`SWAP_FORMAT_VERSION`]) is written
//! when the agent reported the swap done, right after its attachment and before any step the
//! new model decided, so a streaming reader knows the model before it needs it. Its keys:
//!
//! | key | value |
//! |---|---|
//! | `format` | `formation.swapped_model v1` |
//! | `robot`, `tick`, `request_id` | the robot, the first tick the new model decided, the request |
//! | `model_id` | the id the agent reported (file stem and FNV-1a content hash) |
//! | `path` | the model file the request named, on the world's host (empty when unknown) |
//! | `sha256` | the stored bytes' SHA-256 (empty when not stored) |
//! | `stored` | `attachment models/<sha256>.onnx`, `shipped` or `not stored (<reason>)` |
//!
//! The bytes are the file's at the request's path, or those that came with the request over the
//! network (Zenoh). A model is stored only when they are the ones the agent loaded: their content
//! hash must be the one in the agent's model id ([`check_swapped_bytes`]); a file changed on disk
//! since the swap, one that cannot be read or is larger than
//! [`crate::model_files::MAX_ATTACHED_MODEL_BYTES`] is recorded as not stored, with the reason.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use formation_proto::model_id::{content_hash, content_hash_of_id};

use crate::read_error::ReadError;

/// The name of a swapped-in model's metadata record.
pub const SWAP_METADATA: &str = "formation.swapped_model";

/// The record's format name, the start of its `format` key.
pub const SWAP_FORMAT: &str = "formation.swapped_model";

/// The record format's version: a reader refuses another.
pub const SWAP_FORMAT_VERSION: u32 = 1;

/// Where a swapped-in model's bytes are.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SwapStorage {
    /// In the recording, as the attachment of this name.
    Attachment(String),
    /// A shipped model, at its path (checked against the SHA-256).
    Shipped,
    /// Nowhere in the recording: why.
    NotStored(String),
}

/// One swapped-in model, as its metadata record holds it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SwappedModel {
    /// The robot.
    pub robot: u32,
    /// The first tick the new model decided.
    pub tick: u64,
    /// The swap request's id.
    pub request_id: u64,
    /// The model id the replay steps name.
    pub model_id: String,
    /// The model file the request named (empty when unknown).
    pub path: PathBuf,
    /// The stored bytes' SHA-256, as lowercase hex (empty when not stored).
    pub sha256: String,
    /// Where its bytes are.
    pub storage: SwapStorage,
}

impl SwappedModel {
    /// The record's keys.
    pub fn to_metadata(&self) -> BTreeMap<String, String> {
        let stored = match &self.storage {
            SwapStorage::Attachment(name) => format!("attachment {name}"),
            SwapStorage::Shipped => "shipped".to_owned(),
            SwapStorage::NotStored(why) => format!("not stored ({why})"),
        };
        [
            ("format", format!("{SWAP_FORMAT} v{SWAP_FORMAT_VERSION}")),
            ("robot", self.robot.to_string()),
            ("tick", self.tick.to_string()),
            ("request_id", self.request_id.to_string()),
            ("model_id", self.model_id.clone()),
            ("path", self.path.display().to_string()),
            ("sha256", self.sha256.clone()),
            ("stored", stored),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_owned(), v))
        .collect()
    }

    /// The record read back; a missing or malformed key, or another format version, is
    /// [`ReadError::Metadata`] (`recording` names the file).
    pub fn from_metadata(
        recording: &Path,
        raw: &BTreeMap<String, String>,
    ) -> Result<SwappedModel, ReadError> {
        let bad = |key: &str, why: String| ReadError::Metadata {
            path: recording.to_path_buf(),
            record: SWAP_METADATA,
            key: key.to_owned(),
            why,
        };
        let get = |key: &str| raw.get(key).ok_or_else(|| bad(key, "missing".into()));
        let expected = format!("{SWAP_FORMAT} v{SWAP_FORMAT_VERSION}");
        let format = get("format")?;
        if *format != expected {
            return Err(bad(
                "format",
                format!(
                    "`{format}`, this build reads `{expected}`: replay it with the formation \
                     that recorded it"
                ),
            ));
        }
        let number = |key: &str| {
            get(key)?
                .parse::<u64>()
                .map_err(|_| bad(key, "not a whole number".into()))
        };
        let robot =
            u32::try_from(number("robot")?).map_err(|_| bad("robot", "too large".into()))?;
        let stored = get("stored")?;
        let storage = if stored == "shipped" {
            SwapStorage::Shipped
        } else if let Some(name) = stored.strip_prefix("attachment ") {
            SwapStorage::Attachment(name.to_owned())
        } else if let Some(why) = stored
            .strip_prefix("not stored (")
            .and_then(|rest| rest.strip_suffix(')'))
        {
            SwapStorage::NotStored(why.to_owned())
        } else {
            return Err(bad(
                "stored",
                "neither `attachment NAME`, `shipped` nor `not stored (WHY)`".into(),
            ));
        };
        let sha256 = get("sha256")?.clone();
        if sha256.is_empty() && !matches!(storage, SwapStorage::NotStored(_)) {
            return Err(bad("sha256", "empty for a stored model".into()));
        }
        Ok(SwappedModel {
            robot,
            tick: number("tick")?,
            request_id: number("request_id")?,
            model_id: get("model_id")?.clone(),
            path: PathBuf::from(get("path")?),
            sha256,
            storage,
        })
    }
}

/// Why the bytes read for a swapped-in model are not the ones the agent loaded, if they are not:
/// their content hash must be the one in the agent's `model_id`.
pub fn check_swapped_bytes(model_id: &str, bytes: &[u8]) -> Result<(), String> {
    let Some(expected) = content_hash_of_id(model_id) else {
        return Err(format!(
            "the agent's model id `{model_id}` carries no content hash to check the file against"
        ));
    };
    let found = content_hash(bytes);
    if found == expected {
        Ok(())
    } else {
        Err(format!(
            "the file changed since the agent loaded it: its content hash is {found:08x}, the \
             agent's model id `{model_id}` says {expected:08x}"
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::read::tests::read_items;
    use formation_proto::SwapDone;

    fn swapped(storage: SwapStorage) -> SwappedModel {
        SwappedModel {
            robot: 1,
            tick: 120,
            request_id: 7,
            model_id: "second-0123abcd".into(),
            path: PathBuf::from("/tmp/x/second.onnx"),
            sha256: if matches!(storage, SwapStorage::NotStored(_)) {
                String::new()
            } else {
                "ab".repeat(32)
            },
            storage,
        }
    }

    #[test]
    fn the_record_round_trips_for_each_storage() {
        for storage in [
            SwapStorage::Attachment(format!("models/{}.onnx", "ab".repeat(32))),
            SwapStorage::Shipped,
            SwapStorage::NotStored("the file changed (a, b)".into()),
        ] {
            let model = swapped(storage);
            let raw = model.to_metadata();
            assert_eq!(raw["format"], "formation.swapped_model v1");
            let back = SwappedModel::from_metadata(Path::new("r.mcap"), &raw).unwrap();
            assert_eq!(back, model);
        }
    }

    #[test]
    fn another_version_or_a_malformed_key_is_refused_naming_the_key() {
        let good = swapped(SwapStorage::Shipped).to_metadata();
        let cases = [
            ("format", "formation.swapped_model v2"),
            ("robot", "one"),
            ("tick", "-3"),
            ("stored", "somewhere"),
            ("sha256", ""),
        ];
        for (key, value) in cases {
            let mut raw = good.clone();
            raw.insert(key.into(), value.into());
            let err = SwappedModel::from_metadata(Path::new("r.mcap"), &raw).unwrap_err();
            let text = err.to_string();
            assert!(text.contains(key) && text.contains(SWAP_METADATA), "{text}");
        }
        let mut raw = good;
        raw.remove("model_id");
        let err = SwappedModel::from_metadata(Path::new("r.mcap"), &raw).unwrap_err();
        assert!(err.to_string().contains("model_id"), "{err}");
    }

    fn tick(k: u64, model_id: &str) -> crate::TickRecord {
        use formation_proto::{Goal, Pose, WheelCmd};
        crate::TickRecord {
            tick: k,
            time: k as f64 * 0.05,
            goal: Goal::new(0.0, 1.0, 0.2),
            poses: vec![Pose::new(0.0, 0.0, 0.0); 2],
            wheel_speeds: vec![WheelCmd::default(); 2],
            scans: vec![vec![1.0; 4]; 2],
            commands: vec![crate::SentCommand::in_process(WheelCmd::default()); 2],
            model_ids: vec![model_id.to_owned(); 2],
        }
    }

    #[test]
    fn a_swapped_in_model_is_stored_mid_file_once_before_its_steps_and_survives_a_crash() {
        use crate::RecordingItem::{Model, Step, Swap};
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("second.onnx");
        std::fs::write(&model, b"second model").unwrap();
        let id = formation_proto::model_id::model_id(&model, b"second model");
        let team = crate::TeamSetup {
            n_robots: 2,
            max_range: 4.0,
            wheel_separation: 0.2,
            neighbours: formation_proto::NeighbourRule::AllPairs,
            wheels: formation_proto::WheelLimits::default(),
        };
        let path = dir.path().join("r.mcap");
        let mut rec =
            crate::RecordingFile::create_with_metadata(&path, team, 1.0, BTreeMap::new()).unwrap();
        rec.write_tick(&tick(0, "first-00000000")).unwrap();
        let event = |robot: usize| SwapDone {
            robot,
            tick: 1,
            request_id: robot as u64 + 5,
            model_id: id.clone(),
            path: Some(model.clone()),
            model: None,
        };
        let name = format!("models/{}.onnx", crate::models::sha256_hex(b"second model"));
        let stored = rec.write_swap(&event(0)).unwrap();
        assert_eq!(stored.storage, SwapStorage::Attachment(name.clone()));
        // A crash now: the file as it stands holds the model and its record.
        let crashed = dir.path().join("crashed.mcap");
        std::fs::copy(&path, &crashed).unwrap();
        assert_eq!(rec.write_swap(&event(1)).unwrap().storage, stored.storage);
        std::fs::write(&model, b"changed on disk").unwrap();
        let changed = rec.write_swap(&event(0)).unwrap();
        let SwapStorage::NotStored(why) = &changed.storage else {
            panic!("{changed:?}");
        };
        assert!(why.contains("changed since the agent loaded it"), "{why}");
        assert!(changed.sha256.is_empty());
        // Bytes that came over the network with the request, under the agent's own file name.
        let sent = SwapDone {
            model_id: formation_proto::model_id::model_id(
                Path::new("swap-7.onnx"),
                b"second model",
            ),
            path: Some(PathBuf::from("sent-over-zenoh/second.onnx")),
            model: Some(b"second model".to_vec()),
            ..event(1)
        };
        assert_eq!(rec.write_swap(&sent).unwrap().storage, stored.storage);
        let damaged = SwapDone {
            model: Some(b"damaged".to_vec()),
            ..sent
        };
        let refused = rec.write_swap(&damaged).unwrap();
        assert!(
            matches!(refused.storage, SwapStorage::NotStored(_)),
            "{refused:?}"
        );
        rec.write_tick(&tick(1, &id)).unwrap();
        rec.finish(None).unwrap();

        let (all, end) = read_items(&path);
        end.unwrap();
        let models: Vec<_> = all.iter().filter(|i| matches!(i, Model { .. })).collect();
        assert_eq!(
            models,
            [&Model {
                name,
                bytes: b"second model".to_vec()
            }]
        );
        let first_swap = all.iter().position(|i| matches!(i, Swap(_))).unwrap();
        let first_step_of_it = all
            .iter()
            .position(|i| matches!(i, Step(s) if s.model_id == id))
            .unwrap();
        assert!(first_swap < first_step_of_it);
        assert_eq!(all[first_swap], Swap(stored.clone()));
        assert_eq!(all.iter().filter(|i| matches!(i, Swap(_))).count(), 5);

        let (kept, end) = read_items(&crashed);
        assert!(matches!(end, Err(ReadError::Truncated { .. })), "{end:?}");
        assert!(kept.contains(&Swap(stored)), "{kept:?}");
        assert!(kept.iter().any(|i| matches!(i, Model { .. })));
    }

    #[test]
    fn bytes_are_stored_only_when_their_content_hash_is_the_agents() {
        let id = formation_proto::model_id::model_id(Path::new("second.onnx"), b"loaded");
        assert_eq!(check_swapped_bytes(&id, b"loaded"), Ok(()));
        let changed = check_swapped_bytes(&id, b"changed on disk").unwrap_err();
        assert!(
            changed.contains("changed since the agent loaded it"),
            "{changed}"
        );
        let no_hash = check_swapped_bytes("expert", b"loaded").unwrap_err();
        assert!(no_hash.contains("no content hash"), "{no_hash}");
    }
}
