//! Reading an MCAP recording and its replay steps (formation-record): what `formation replay`
//! does with a file someone hands it.
//!
//! Case: the file's bytes, written to the scratch folder and read with
//! [`RecordingReader::open`] and [`RecordingReader::next_item`] to the end (the models, the run's
//! metadata, every replay step, the swap records). Decoded means the whole file was read.
//!
//! The seeds are a real recording (zstd chunks with CRCs, as `--record` writes it, with a model
//! swapped in) and the same records rewritten by the `mcap` crate's writer with uncompressed
//! chunks and no CRCs (valid MCAP, as other tools write it), so that mutations reach the records
//! inside chunks instead of stopping at a checksum.

use std::borrow::Cow;
use std::io::Cursor;

use formation_record::{FinalSample, RecordingFile, RecordingReader};
use mcap::records::Record;

use super::{Refusal, Scratch, Seed, Target, sample, seed_error};
use crate::FuzzError;
use crate::mutate::Shape;

/// The target.
pub const TARGET: Target = Target {
    name: "recording",
    about: "an MCAP recording read for a replay: RecordingReader to the end, replay steps included",
    run,
    seeds,
    tokens: &[
        b"\x89MCAP0\r\n",
        b"zstd",
        b"formation.run",
        b"formation/msg/ReplayStep",
        b"/robot_0/replay",
        &[0x00, 0x01, 0x00, 0x00],
        &[0x06],
        &[0x05],
        &[0x09],
    ],
    shape: Shape::Bytes,
};

/// Most items read from one case (a file of more is read no further).
const MAX_ITEMS: usize = 100_000;

fn run(scratch: &Scratch, case: &[u8]) -> Result<(), Refusal> {
    let path = scratch.write("case.mcap", case)?;
    let mut reader = RecordingReader::open(&path).map_err(Refusal::of)?;
    for _ in 0..MAX_ITEMS {
        if reader.next_item().map_err(Refusal::of)?.is_none() {
            return Ok(());
        }
    }
    Ok(())
}

/// The sample run recorded as `--record` writes it.
fn recorded() -> Result<Vec<u8>, FuzzError> {
    let dir = tempfile::tempdir().map_err(seed_error(TARGET.name))?;
    let path = dir.path().join("run.mcap");
    let mut file = RecordingFile::create(&path, sample::setup("recording", Vec::new())?)
        .map_err(seed_error(TARGET.name))?;
    for k in 0..6 {
        file.write_tick(&sample::tick(k))
            .map_err(seed_error(TARGET.name))?;
        if k == 3 {
            file.write_swap(&sample::swap())
                .map_err(seed_error(TARGET.name))?;
        }
    }
    let last = sample::tick(6);
    file.finish(Some(&FinalSample {
        tick: last.tick,
        time: last.time,
        poses: last.poses,
    }))
    .map_err(seed_error(TARGET.name))?;
    std::fs::read(&path).map_err(seed_error(TARGET.name))
}

/// `bytes`' records written again by the `mcap` writer, chunks uncompressed and without CRCs.
fn rewritten(bytes: &[u8]) -> Result<Vec<u8>, FuzzError> {
    let options = mcap::WriteOptions::new()
        .profile("ros2")
        .compression(None)
        .calculate_chunk_crcs(false)
        .calculate_data_section_crc(false)
        .calculate_summary_section_crc(false)
        .calculate_attachment_crcs(false);
    let mut writer = options
        .create(Cursor::new(Vec::new()))
        .map_err(seed_error(TARGET.name))?;
    for record in mcap::read::ChunkFlattener::new(bytes).map_err(seed_error(TARGET.name))? {
        match record.map_err(seed_error(TARGET.name))? {
            Record::Schema { header, data } => {
                writer
                    .add_schema_with_id(header.id, &header.name, &header.encoding, &data)
                    .map_err(seed_error(TARGET.name))?;
            }
            Record::Channel(c) => {
                writer
                    .add_channel_with_id(
                        c.id,
                        c.schema_id,
                        &c.topic,
                        &c.message_encoding,
                        &c.metadata,
                    )
                    .map_err(seed_error(TARGET.name))?;
            }
            Record::Message { header, data } => {
                writer
                    .write_to_known_channel(&header, &data)
                    .map_err(seed_error(TARGET.name))?;
            }
            Record::Attachment { header, data, .. } => {
                writer
                    .attach(&mcap::Attachment {
                        log_time: header.log_time,
                        create_time: header.create_time,
                        name: header.name,
                        media_type: header.media_type,
                        data: Cow::Borrowed(&data),
                    })
                    .map_err(seed_error(TARGET.name))?;
            }
            Record::Metadata(metadata) => writer
                .write_metadata(&metadata)
                .map_err(seed_error(TARGET.name))?,
            _ => {}
        }
    }
    writer.finish().map_err(seed_error(TARGET.name))?;
    Ok(writer.into_inner().into_inner())
}

fn seeds() -> Result<Vec<Seed>, FuzzError> {
    let zstd = recorded()?;
    let plain = rewritten(&zstd)?;
    Ok(vec![
        ("run-zstd.mcap".into(), zstd),
        ("run-plain.mcap".into(), plain),
    ])
}
