//! `formation record --connect tcp/HOST:PORT --run-id ID --credentials recorder.json --out
//! FILE.mcap`: records a live Zenoh team from outside, into the very file `--record` writes for
//! the same run (message for message; see [`formation_record::live`]); with `--transport ros2`
//! (and no `--credentials`), a live ROS 2 team, whose world serves the same record channel; on
//! `tls/`, with the recorder's certificate (`--credentials DIR/recorder.json` of the team's
//! `formation credentials --tls` folder), which the ROS 2 router lets read every topic and the
//! record channel, and publish nothing.
//!
//! A Zenoh team needs the read-only recorder login that `formation credentials` writes
//! (`recorder.json`): without `--credentials`, or with another user's login (an agent's, the
//! operator's), it is refused before it connects, naming the fix; the world's router refuses a
//! connection without a valid login and its access rules let only the recorder read the record
//! channel. A ROS 2 team on `tcp/` has no logins or access rules (as ROS 2 without SROS2: whoever
//! reaches its router reads its topics too), so its recorder connects without one; on `tls/` its
//! router names principals by certificate, so the recorder shows its certificate and no password.
//!
//! It connects, subscribes, and asks for the setup of a run under way: started before the run,
//! it records from its first tick; started while a run plays, from the tick it joined at (the
//! metadata says which, `live.first_tick`). It ends when the launch's last run has ended (exit
//! 0), when the team goes (its world ended or the link was lost: the file is finished with what
//! arrived, exit 2, unless every run was recorded), or on Ctrl-C or SIGTERM (the file is
//! finished, exit 130 or 143).

use std::path::PathBuf;
use std::time::Duration;

use formation_proto::exit::TerminationSignal;
use formation_proto::wire::RunId;
use formation_record::live::{LiveRecording, LiveRunDone, decode};
use formation_record::{RecordTarget, RecordingSummary};
use formation_runtime::transport::Transport;
use formation_transport_zenoh::{
    Endpoint, Login, RecorderAccess, RecorderEvent, RecorderLink, credentials,
};

use crate::args::RecordArgs;
use crate::launch::supervisor::LaunchError;

/// How long the recorder waits between looks at its link while nothing comes.
const IDLE_WAIT: Duration = Duration::from_millis(500);

/// A recording from outside that ended before the team's last run did.
#[derive(Debug, thiserror::Error)]
#[error(
    "the team at {endpoint} went before its last run ended (its world ended early, or the link \
     was lost){}",
    kept_note(kept)
)]
pub struct TeamGone {
    /// The endpoint.
    pub endpoint: String,
    /// The files finished with what arrived.
    pub kept: Vec<PathBuf>,
}

fn kept_note(kept: &[PathBuf]) -> String {
    if kept.is_empty() {
        "; nothing was recorded".to_owned()
    } else {
        let files: Vec<String> = kept.iter().map(|p| p.display().to_string()).collect();
        format!("; what arrived is kept in {}", files.join(", "))
    }
}

/// How the recorder shows itself: a Zenoh team's `recorder.json` (required); a ROS 2 team on
/// `tls/`, the recorder's certificate beside its `recorder.json` (required: its router names
/// principals by certificate); a ROS 2 team on `tcp/`, nothing (it has no logins, and
/// `--credentials` is refused there, as it is for `formation run`).
fn recorder_login(args: &RecordArgs, endpoint: &Endpoint) -> anyhow::Result<Option<Login>> {
    args.transport
        .refuse_network_flags(&[(true, "formation record --connect")])?;
    if let Some(plugin) = args.transport.plugin() {
        anyhow::bail!(
            "formation record --connect needs --transport zenoh or ros2: the {} transport has no \
             record channel (record the run with `formation run --record` instead)",
            plugin.name()
        );
    }
    let ros2 = args.transport == Transport::Ros2;
    if ros2 && !endpoint.is_tls() {
        if args.credentials.is_some() {
            anyhow::bail!(
                "--credentials needs --transport zenoh, or a ROS 2 team on tls/: a ROS 2 team \
                 on {endpoint} has no logins, so its recorder takes none"
            );
        }
        return Ok(None);
    }
    let Some(login_file) = &args.credentials else {
        if ros2 {
            anyhow::bail!(
                "a ROS 2 team on {endpoint} admits its recorder by the recorder's certificate: \
                 pass --credentials DIR/recorder.json of the team's `formation credentials \
                 --tls` folder (recorder.pem, recorder.key.pem and ca.pem beside it)"
            );
        }
        anyhow::bail!(
            "formation record --connect needs the team's recorder login: pass --credentials \
             DIR/recorder.json from the team's credentials folder (`formation credentials \
             --robots N --out DIR` writes it; `formation run --transport zenoh` without \
             --credentials makes one in <out>/credentials/<run id>/)"
        );
    };
    Ok(Some(credentials::read_recorder(login_file)?))
}

/// `formation record`.
pub fn record_command(args: &RecordArgs) -> anyhow::Result<()> {
    let endpoint = Endpoint::parse(&args.connect)?;
    let login = recorder_login(args, &endpoint)?;
    let run = RunId::new(&args.run_id)?;
    RecordTarget::File(args.out.clone()).check()?;
    // The recording never goes over the credentials it logs in with.
    if let Some(credentials) = &args.credentials {
        crate::paths::refuse_overwriting_inputs(
            &[("--out", &args.out, "run.mcap")],
            &[],
            &[("--credentials", credentials)],
        )?;
    }
    let timeout = crate::launch::positive_seconds("--timeout-s", args.timeout_s)?;
    let access = match &login {
        None => RecorderAccess::Open,
        Some(login) if args.transport == Transport::Ros2 => RecorderAccess::Certificate(login),
        Some(login) => RecorderAccess::Login(login),
    };
    let link = RecorderLink::connect(&endpoint, access, &run, timeout)?;
    println!("connected to run {run} at {endpoint}; recording its runs");
    let mut recording =
        LiveRecording::new(&args.out, &format!("formation record --connect {endpoint}"));
    let mut kept = Vec::new();
    let outcome = record_until_done(&link, &mut recording, &mut kept);
    let ended = recording.abandon()?;
    if let Some(done) = &ended {
        report_run(done);
        kept.push(done.summary.path.clone());
    }
    match outcome? {
        Ended::AllRuns => Ok(()),
        Ended::TeamGone => Err(TeamGone {
            endpoint: endpoint.to_string(),
            kept,
        }
        .into()),
        Ended::Stopped(signal) => Err(LaunchError::Interrupted(signal).into()),
    }
}

/// How a recording from outside ended.
enum Ended {
    /// The launch's last run ended.
    AllRuns,
    /// The team went first.
    TeamGone,
    /// SIGINT or SIGTERM.
    Stopped(TerminationSignal),
}

/// Takes the link's events into `recording` until the launch's last run ends, the team goes or
/// a signal comes; each finished file goes to `kept`.
fn record_until_done(
    link: &RecorderLink,
    recording: &mut LiveRecording,
    kept: &mut Vec<PathBuf>,
) -> anyhow::Result<Ended> {
    let mut asked = false;
    loop {
        let Some(event) = link.next(IDLE_WAIT) else {
            if !asked && !recording.has_setup() {
                // Joined while a run plays (or before any): ask once for its setup.
                asked = true;
                if let Some(bytes) = link.ask_setup() {
                    take(recording, &bytes, kept)?;
                }
            }
            continue;
        };
        match event {
            RecorderEvent::Message(bytes) => {
                if take(recording, &bytes, kept)?.is_some_and(|done| done.last_run && done.ended) {
                    return Ok(Ended::AllRuns);
                }
                if !asked && !recording.has_setup() {
                    asked = true;
                    if let Some(bytes) = link.ask_setup() {
                        take(recording, &bytes, kept)?;
                    }
                }
            }
            RecorderEvent::WorldGone => return Ok(Ended::TeamGone),
            RecorderEvent::Stopped(signal) => return Ok(Ended::Stopped(signal)),
        }
    }
}

/// Takes one message; a run it finished is reported and its file added to `kept`.
fn take(
    recording: &mut LiveRecording,
    bytes: &[u8],
    kept: &mut Vec<PathBuf>,
) -> anyhow::Result<Option<LiveRunDone>> {
    let done = recording.take(decode(bytes)?)?;
    if let Some(done) = &done {
        report_run(done);
        kept.push(done.summary.path.clone());
    }
    Ok(done)
}

/// Says where a run's recording is, and whether it is the whole run.
fn report_run(done: &LiveRunDone) {
    let RecordingSummary {
        path,
        messages,
        bytes,
        ..
    } = &done.summary;
    let whole = match (done.first_tick, done.ended) {
        (Some(0), true) => String::new(),
        (Some(first), true) => format!("; joined late: from tick {first}"),
        (Some(first), false) => format!(
            "; ticks {first}..{} only: the run did not end while recording",
            first + done.ticks
        ),
        (None, _) => "; no tick arrived".to_owned(),
    };
    println!(
        "recorded run {} to {} ({messages} messages, {:.1} MB{whole})",
        done.run_index,
        path.display(),
        *bytes as f64 / 1e6
    );
}
