//! A short run recorded through [`RecordedController`] and read back with the `mcap` crate's
//! readers: every topic, the chunking, the metadata, an attached model, the replay channel bit
//! for bit against what the controller was given, and a file cut short.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use formation_proto::WheelCmd;
use formation_proto::control::{Controller, ControllerError, controller_fn};
use formation_record::{
    LaunchInfo, ReadError, RecordError, RecordedController, Recorder, RecordingItem,
    RecordingReader, RecordingSetup, ReplayStep,
};
use formation_ros2::{LaserScan, RosMessage, TfMessage, Twist};
use formation_world::{RunSpec, Scenario, run_episode};

fn spec(robots: usize, seconds: f64) -> RunSpec {
    let text = format!(
        r#"
name = "record-test"
robots = {robots}
duration_s = {seconds}
seed = 5
[goal]
v_star = 0.3
d_star = 1.5
[heading]
schedule = "ramp"
omega = 0.3
[lidar]
beams = 90
noise_std = 0.01
"#
    );
    Scenario::from_toml_str(&text, "record-test")
        .unwrap()
        .run_spec(5, 0)
}

/// What the controller was given at one tick: the tick, the scans, the headings, the goal.
type Seen = (u64, Vec<Vec<f32>>, Vec<f64>, formation_proto::Goal);

/// Turns gently, and keeps every observation it was given in `seen`.
fn turning(seen: &mut Vec<Seen>) -> impl Controller {
    controller_fn(move |obs, out| {
        for (i, slot) in out.iter_mut().enumerate() {
            *slot = WheelCmd {
                left: 0.1 + 0.01 * i as f64 + 1e-17 * obs.tick as f64,
                right: 0.2 / 3.0,
            };
        }
        let headings = obs.poses.iter().map(|p| p.theta).collect();
        seen.push((obs.tick, obs.scans.to_vec(), headings, obs.goal));
        Ok(())
    })
}

fn launch(models: Vec<PathBuf>) -> LaunchInfo {
    LaunchInfo {
        scenario: "record-test".into(),
        base_seed: Some(5),
        clock: "in-process".into(),
        controller: "policy".into(),
        models,
        shipped_models: None,
    }
}

/// Records `spec` into `path`; returns what the controller saw and the trajectory.
fn record(
    spec: &RunSpec,
    path: &Path,
    models: Vec<PathBuf>,
) -> (Vec<Seen>, formation_world::Trajectory) {
    let recorder = Recorder::start(path, RecordingSetup::for_run(spec, &launch(models))).unwrap();
    let mut seen = Vec::new();
    let trajectory = {
        let mut inner = turning(&mut seen);
        let mut failed = |e: &RecordError| panic!("{e}");
        let ids = vec!["m".to_owned(); spec.n_robots];
        let mut recorded = RecordedController::new(&mut inner, recorder, ids, &mut failed);
        let trajectory = run_episode(spec, &mut recorded, &mut |_, _| {}).unwrap();
        let summary = recorded.finish(Some(&trajectory)).unwrap().unwrap();
        assert!(summary.bytes > 0 && summary.messages > 0);
        trajectory
    };
    (seen, trajectory)
}

#[test]
fn a_recording_holds_every_topic_in_one_second_chunks_and_the_replay_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let spec = spec(3, 2.5);
    let (seen, trajectory) = record(&spec, &path, Vec::new());
    let bytes = std::fs::read(&path).unwrap();

    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    // 2.5 s of ticks plus the final sample at 2.5 s: chunks for seconds 0, 1 and 2, plus the
    // chunk of the static frames.
    assert_eq!(summary.chunk_indexes.len(), 4);
    for chunk in &summary.chunk_indexes {
        assert!(chunk.message_end_time - chunk.message_start_time < 1_000_000_000);
        assert_eq!(chunk.compression, "zstd");
    }

    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    let mut tf_poses = Vec::new();
    let mut replays = Vec::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let channel = &message.channel;
        *counts.entry(channel.topic.clone()).or_default() += 1;
        let schema = channel.schema.as_ref().unwrap();
        assert_eq!(
            (schema.encoding.as_str(), channel.message_encoding.as_str()),
            ("ros2msg", "cdr")
        );
        match channel.topic.as_str() {
            "/tf" => {
                let tf = TfMessage::from_cdr(&message.data).unwrap();
                tf_poses.push((message.log_time, tf.transforms[0].clone()));
            }
            "/robot_1/scan" => {
                let scan = LaserScan::from_cdr(&message.data).unwrap();
                assert_eq!(scan.ranges.len(), 90);
                assert_eq!(scan.header.frame_id, "robot_1/laser");
            }
            "/robot_2/cmd_vel" => {
                Twist::from_cdr(&message.data).unwrap();
            }
            t if t.ends_with("/replay") => {
                replays.push(ReplayStep::from_cdr(&message.data).unwrap())
            }
            _ => {}
        }
    }
    let ticks = spec.ticks() as usize;
    assert_eq!(ticks, 50);
    for robot in 0..3 {
        for topic in ["scan", "odom", "cmd_vel", "replay"] {
            assert_eq!(counts[&format!("/robot_{robot}/{topic}")], ticks, "{topic}");
        }
    }
    assert_eq!(counts["/tf"], 3 * (ticks + 1));
    assert_eq!(counts["/tf_static"], 3);
    assert_eq!(counts["/formation/edges"], ticks + 1);
    assert_eq!(counts["/formation/goal/heading"], ticks);

    // /tf places each robot where the trajectory has it, at each sample's time.
    for (log_time, edge) in &tf_poses {
        let robot: usize = edge.child_frame_id["robot_".len()..]
            .split('/')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        let k = (*log_time as f64 / 1e9 / spec.world.dt).round() as usize;
        let pose = trajectory.poses[k][robot];
        assert_eq!(edge.transform.translation.x, pose.x);
        assert_eq!(edge.transform.translation.y, pose.y);
    }

    // The replay channel holds exactly what the controller was given and what it answered.
    assert_eq!(replays.len(), 3 * ticks);
    for step in &replays {
        let (tick, scans, headings, goal) = &seen[step.tick as usize];
        assert_eq!(*tick, step.tick);
        let robot = step.robot as usize;
        let bits = |v: &[f32]| v.iter().map(|r| r.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&step.ranges), bits(&scans[robot]));
        assert_eq!(step.heading.to_bits(), headings[robot].to_bits());
        assert_eq!(step.goal, *goal);
        let sent = trajectory.commands[step.tick as usize][robot];
        assert_eq!(step.command.left.to_bits(), sent.left.to_bits());
        assert_eq!(step.command.right.to_bits(), sent.right.to_bits());
        assert_eq!(step.model_id, "m");
    }
}

#[test]
fn metadata_names_the_run_and_a_model_from_elsewhere_is_attached() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("mine.onnx");
    std::fs::write(&model, b"not really onnx, but bytes to keep").unwrap();
    let path = dir.path().join("run.mcap");
    let spec = spec(2, 0.2);
    record(&spec, &path, vec![model.clone(), model.clone()]);
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let index = &summary.metadata_indexes[0];
    let meta = mcap::read::metadata(&bytes, index).unwrap();
    assert_eq!(meta.name, "formation.run");
    let m = &meta.metadata;
    assert_eq!(m["scenario"], "record-test");
    assert_eq!(m["seed"], "5");
    assert_eq!(m["run_index"], "0");
    assert_eq!(m["robot_models"], "0,0");
    assert_eq!(m["model.0.path"], model.display().to_string());
    let sha = &m["model.0.sha256"];
    assert_eq!(sha.len(), 64);
    assert_eq!(m["model.0.stored"], format!("attachment models/{sha}.onnx"));
    let attachment = mcap::read::attachment(&bytes, &summary.attachment_indexes[0]).unwrap();
    assert_eq!(&*attachment.data, b"not really onnx, but bytes to keep");
}

#[test]
fn a_file_cut_short_reads_up_to_its_last_whole_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let spec = spec(3, 3.0);
    record(&spec, &path, Vec::new());
    let bytes = std::fs::read(&path).unwrap();
    // Cut inside the last data chunk: the summary and the end are gone, as after a crash.
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let last = summary.chunk_indexes.last().unwrap();
    let cut = &bytes[..(last.chunk_start_offset + last.chunk_length / 2) as usize];
    let mut latest = 0;
    for message in mcap::MessageStream::new(cut).unwrap() {
        match message {
            Ok(m) => latest = latest.max(m.log_time),
            Err(_) => break,
        }
    }
    // The chunks of seconds 0 and 1 survive whole.
    assert!(latest >= 1_950_000_000, "{latest}");
}

/// Every replay step `RecordingReader` hands out of `path`, and how the file ended.
fn read_steps(path: &Path) -> (Vec<ReplayStep>, Result<(), ReadError>) {
    let mut reader = RecordingReader::open(path).unwrap();
    let mut steps = Vec::new();
    loop {
        match reader.next_item() {
            Ok(Some(RecordingItem::Step(step))) => steps.push(step),
            Ok(Some(_)) => {}
            Ok(None) => return (steps, Ok(())),
            Err(e) => return (steps, Err(e)),
        }
    }
}

/// How many replay messages the `mcap` crate's own streaming reader finds in `bytes` before it
/// stops.
fn replay_messages_in(bytes: &[u8]) -> usize {
    let mut count = 0;
    for message in mcap::MessageStream::new(bytes).unwrap() {
        match message {
            Ok(m) if m.channel.topic.ends_with("/replay") => count += 1,
            Ok(_) => {}
            Err(_) => break,
        }
    }
    count
}

/// The header the MCAP writer puts at the start of a chunk it has not closed yet: the chunk
/// opcode, and the lengths, sizes and CRC as placeholders (all ones), 53 bytes for zstd.
fn unclosed_chunk_header() -> Vec<u8> {
    let mut header = vec![0x06];
    header.extend(u64::MAX.to_le_bytes()); // record length
    header.extend(0u64.to_le_bytes()); // message start time
    header.extend(0u64.to_le_bytes()); // message end time
    header.extend(u64::MAX.to_le_bytes()); // uncompressed size
    header.extend(u32::MAX.to_le_bytes()); // uncompressed CRC
    header.extend(4u32.to_le_bytes());
    header.extend(b"zstd");
    header.extend(u64::MAX.to_le_bytes()); // compressed size
    assert_eq!(header.len(), 53);
    header
}

/// A crash or a full disk stops the writer at any byte: at a chunk boundary, inside a chunk's
/// header, just after it, or inside a chunk it has not closed (its header's length still the
/// placeholder, its data partly written). Every such file reads up to its last whole chunk: the
/// steps before the cut, each bit for bit, then `Truncated` with the byte where the readable part
/// ends.
#[test]
fn a_recording_cut_at_every_chunk_boundary_and_after_every_chunk_header_reads_to_its_last_whole_chunk()
 {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    record(&spec(3, 3.0), &path, Vec::new());
    let bytes = std::fs::read(&path).unwrap();
    let (all, end) = read_steps(&path);
    end.unwrap();
    assert_eq!(all.len(), 3 * 60);
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert!(summary.chunk_indexes.len() >= 4);
    let unclosed = unclosed_chunk_header();
    let cut_path = dir.path().join("cut.mcap");
    let mut cases = 0;
    for chunk in &summary.chunk_indexes {
        let start = chunk.chunk_start_offset as usize;
        let end = start + chunk.chunk_length as usize;
        // The record's opcode and length, then the header's fixed fields and compression name.
        let header_end = start + 9 + 8 + 8 + 8 + 4 + 4 + chunk.compression.len() + 8;
        let data = &bytes[header_end..end];
        let crashed = |tail: &[u8]| [&bytes[..start], &unclosed, tail].concat();
        // (file, where its readable part ends, whether an unclosed chunk follows it)
        let cuts: Vec<(Vec<u8>, usize, bool)> = vec![
            (bytes[..start].to_vec(), start, false),
            (bytes[..start + 5].to_vec(), start + 5, false),
            (bytes[..start + 30].to_vec(), start + 30, false),
            (bytes[..header_end].to_vec(), header_end, false),
            (bytes[..end].to_vec(), end, false),
            (crashed(&[]), start, true),
            (crashed(&data[..data.len() / 2]), start, true),
            (crashed(data), start, true),
        ];
        for (cut, readable, unclosed_follows) in cuts {
            std::fs::write(&cut_path, &cut).unwrap();
            let expected = replay_messages_in(&bytes[..readable]);
            let (steps, end) = read_steps(&cut_path);
            let what = format!("cut of {} bytes, chunk at {start}", cut.len());
            let err = end.expect_err(&what);
            match &err {
                ReadError::Truncated {
                    read,
                    unclosed_chunk,
                    ..
                } => {
                    assert_eq!(*read, readable as u64, "{what}: {err}");
                    let at = unclosed_follows.then_some(start as u64);
                    assert_eq!(*unclosed_chunk, at, "{what}: {err}");
                }
                other => panic!("{what}: not Truncated: {other}"),
            }
            let message = err.to_string();
            assert!(message.contains(&format!("byte {readable}")), "{message}");
            assert!(message.contains("record the run again"), "{message}");
            if unclosed_follows {
                assert!(message.contains("never closed"), "{message}");
            }
            assert_eq!(steps.len(), expected, "{what}");
            assert_eq!(steps[..], all[..expected], "{what}");
            cases += 1;
        }
    }
    // Whole chunks were read from some cuts, so the cuts compared something.
    assert!(replay_messages_in(&bytes[..summary.chunk_indexes[2].chunk_start_offset as usize]) > 0);
    assert_eq!(cases, 8 * summary.chunk_indexes.len());
}

/// A file that holds the MCAP magic and then stops (a recorder killed as it started) is "too
/// short", not "not MCAP".
#[test]
fn a_file_cut_just_after_the_magic_is_too_short_not_foreign() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    record(&spec(3, 1.0), &path, Vec::new());
    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..20]).unwrap();
    let err = read_steps(&cut).1.unwrap_err();
    assert!(matches!(err, ReadError::TooShort { size: 20, .. }), "{err}");
    let message = err.to_string();
    assert!(
        message.contains("too short") && message.contains("truncated"),
        "{message}"
    );
    assert!(
        !message.contains("does not start with the MCAP magic"),
        "{message}"
    );
}

/// A run stopped early (Ctrl-C) is a whole MCAP file: its end record says it is incomplete and
/// why, as the run log does; a run played to its end says it is complete (issue 39).
#[test]
fn the_recording_says_whether_the_run_played_to_its_end() {
    use formation_record::RunEnd;
    let dir = tempfile::tempdir().unwrap();
    let spec = spec(3, 1.0);
    let ends = |path: &Path| {
        let mut reader = RecordingReader::open(path).unwrap();
        let mut ends = Vec::new();
        while let Some(item) = reader.next_item().unwrap() {
            if let RecordingItem::End(end) = item {
                ends.push(end);
            }
        }
        ends
    };
    let full = dir.path().join("full.mcap");
    record(&spec, &full, Vec::new());
    assert_eq!(ends(&full), [RunEnd::complete()]);

    let stopped = dir.path().join("stopped.mcap");
    let recorder = Recorder::start(
        &stopped,
        RecordingSetup::for_run(&spec, &launch(Vec::new())),
    )
    .unwrap();
    let mut seen = Vec::new();
    let mut inner = stop_after(turning(&mut seen), 5);
    let mut failed = |e: &RecordError| panic!("{e}");
    let ids = vec!["m".to_owned(); spec.n_robots];
    let mut recorded = RecordedController::new(&mut inner, recorder, ids, &mut failed);
    let played = run_episode(&spec, &mut recorded, &mut |_, _| {});
    assert!(played.is_err());
    recorded
        .finish_stopped("interrupted by Ctrl-C")
        .unwrap()
        .unwrap();
    assert_eq!(ends(&stopped), [RunEnd::stopped("interrupted by Ctrl-C")]);
    assert_eq!(read_steps(&stopped).0.len(), 3 * 5);
}

/// Decides `left` ticks with `inner`, then fails as an interrupted controller does.
fn stop_after(mut inner: impl Controller, mut left: usize) -> impl Controller {
    controller_fn(move |obs, out| {
        if left == 0 {
            return Err(ControllerError::new("interrupted"));
        }
        left -= 1;
        inner.commands(obs, out)
    })
}
