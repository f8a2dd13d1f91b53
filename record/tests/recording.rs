//! A short run recorded through [`RecordedController`] and read back with the `mcap` crate's
//! readers: every topic, the chunking, the metadata, an attached model, the replay channel bit
//! for bit against what the controller was given, and a file cut short.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use formation_proto::WheelCmd;
use formation_proto::control::{Controller, ControllerError, Observation};
use formation_record::{
    LaunchInfo, RecordError, RecordedController, Recorder, RecordingSetup, ReplayStep,
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

/// Turns gently, and keeps every observation it was given.
#[derive(Default)]
struct Turning {
    seen: Vec<Seen>,
}

impl Controller for Turning {
    fn commands(
        &mut self,
        obs: &Observation<'_>,
        out: &mut [WheelCmd],
    ) -> Result<(), ControllerError> {
        for (i, slot) in out.iter_mut().enumerate() {
            *slot = WheelCmd {
                left: 0.1 + 0.01 * i as f64 + 1e-17 * obs.tick as f64,
                right: 0.2 / 3.0,
            };
        }
        let headings = obs.poses.iter().map(|p| p.theta).collect();
        self.seen
            .push((obs.tick, obs.scans.to_vec(), headings, obs.goal));
        Ok(())
    }
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

/// Records `spec` into `path`; returns the controller (with what it saw) and the trajectory.
fn record(
    spec: &RunSpec,
    path: &Path,
    models: Vec<PathBuf>,
) -> (Turning, formation_world::Trajectory) {
    let recorder = Recorder::start(path, RecordingSetup::for_run(spec, &launch(models))).unwrap();
    let mut inner = Turning::default();
    let mut failed = |e: &RecordError| panic!("{e}");
    let ids = vec!["m".to_owned(); spec.n_robots];
    let mut recorded = RecordedController::new(&mut inner, recorder, ids, &mut failed);
    let trajectory = run_episode(spec, &mut recorded, &mut |_, _| {}).unwrap();
    let summary = recorded.finish(Some(&trajectory)).unwrap().unwrap();
    assert!(summary.bytes > 0 && summary.messages > 0);
    (inner, trajectory)
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
        let (tick, scans, headings, goal) = &seen.seen[step.tick as usize];
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
