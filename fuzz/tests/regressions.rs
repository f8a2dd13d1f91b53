//! Every finding of formation-fuzz, as the input that found it, against the fixed decoder. The
//! test process caps its address space, so a decoder that asks for gigabytes fails here
//! instead of succeeding on an overcommitting machine.

use std::path::Path;

use formation_record::{ReadError, RecordingReader};

/// Caps this test process's address space at 2 GiB (a decoder that asks for more aborts).
fn limit_memory() {
    let (_, hard) = rlimit::Resource::AS.get().unwrap();
    rlimit::Resource::AS
        .set((2u64 << 30).min(hard), hard)
        .unwrap();
}

/// An MCAP record: its opcode, its body's length (u64, little-endian), its body.
fn record(opcode: u8, body: &[u8]) -> Vec<u8> {
    [&[opcode][..], &(body.len() as u64).to_le_bytes()[..], body].concat()
}

/// An MCAP string: its length (u32, little-endian), its bytes.
fn string(s: &str) -> Vec<u8> {
    [&(s.len() as u32).to_le_bytes()[..], s.as_bytes()].concat()
}

/// Found by the `recording` target (campaign seed 1, first seconds): a metadata record of 33
/// bytes whose map declares a key of 4,294,967,285 bytes; `mcap::parse_record` allocated the
/// declared length (4 GiB) before reading it and the process aborted. Now the reader checks
/// every declared length against the record first and refuses the file as corrupt.
#[test]
fn issue_36_a_metadata_key_longer_than_its_record_is_refused_without_allocating_it() {
    limit_memory();
    let mut file = b"\x89MCAP0\r\n".to_vec();
    file.extend(record(0x01, &[string("ros2"), string("")].concat()));
    let mut metadata = string("formation.run");
    metadata.extend_from_slice(&12u32.to_le_bytes());
    metadata.extend_from_slice(&0xffff_fff5u32.to_le_bytes());
    metadata.extend_from_slice(b"formation");
    file.extend(record(0x0C, &metadata));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.mcap");
    std::fs::write(&path, &file).unwrap();

    let mut reader = RecordingReader::open(&path).unwrap();
    let err = reader.next_item().unwrap_err();
    assert!(matches!(err, ReadError::BadLength { .. }), "{err:?}");
    let chain = format!("{err}: {}", std::error::Error::source(&err).unwrap());
    assert!(chain.contains("corrupt"), "{chain}");
    assert!(
        chain.contains("declares 4294967285 bytes for its metadata"),
        "{chain}"
    );
}

/// Reads `file` to its first error.
fn first_error(path: &Path) -> ReadError {
    let mut reader = RecordingReader::open(path).unwrap();
    loop {
        match reader.next_item() {
            Ok(Some(_)) => {}
            Ok(None) => panic!("{} was read to its end", path.display()),
            Err(e) => return e,
        }
    }
}

/// Found by the `recording` target: a record inside an uncompressed chunk whose length runs
/// past the chunk but not past the file. `mcap`'s file reader subtracted it from the chunk's
/// remaining bytes unchecked: an overflow panic with overflow checks on, and without them the
/// rest of the file read as the chunk's records. Now a chunk's records are read from the
/// chunk's bytes alone, and such a record is a corrupt chunk.
#[test]
fn issue_36_a_record_running_past_its_uncompressed_chunk_is_refused_without_a_panic() {
    let mut inner = vec![0x05];
    inner.extend_from_slice(&200u64.to_le_bytes());
    inner.extend_from_slice(&[0; 22]);
    let mut chunk = Vec::new();
    chunk.extend_from_slice(&0u64.to_le_bytes()); // message start time
    chunk.extend_from_slice(&0u64.to_le_bytes()); // message end time
    chunk.extend_from_slice(&(inner.len() as u64).to_le_bytes()); // uncompressed size
    chunk.extend_from_slice(&0u32.to_le_bytes()); // no CRC
    chunk.extend(string("")); // uncompressed
    chunk.extend_from_slice(&(inner.len() as u64).to_le_bytes());
    chunk.extend_from_slice(&inner);
    let mut file = b"\x89MCAP0\r\n".to_vec();
    file.extend(record(0x01, &[string("ros2"), string("")].concat()));
    file.extend(record(0x06, &chunk));
    for _ in 0..4 {
        file.extend(record(
            0x0C,
            &[string("other"), 0u32.to_le_bytes().to_vec()].concat(),
        ));
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("chunk.mcap");
    std::fs::write(&path, &file).unwrap();

    let err = first_error(&path);
    let source = std::error::Error::source(&err).map(ToString::to_string);
    assert!(
        matches!(err, ReadError::Corrupt { .. })
            && source.as_deref() == Some("Chunk ended in the middle of a record"),
        "{err:?}"
    );
}

/// Found by the `recording` target (campaign seed 1, case 2307; the file is the case): a zstd
/// chunk holding a record that declares about 200 MB. The reader made room to decompress it
/// before finding the chunk far shorter (200 MB resident, for a 43 KB file). Now a record inside
/// a chunk may declare at most 16 MiB, and the file is refused as corrupt at once.
#[test]
fn issue_36_a_chunk_record_of_200_mb_is_refused_before_room_is_made_for_it() {
    limit_memory();
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/findings/recording-chunk-record-of-200-mb.mcap");
    let err = first_error(&path);
    let source = std::error::Error::source(&err)
        .map(ToString::to_string)
        .unwrap_or_default();
    assert!(
        matches!(err, ReadError::Corrupt { .. }) && source.contains("length exceeds limit"),
        "{err:?}"
    );
    let (_, peak) = formation_fuzz::campaign::memory().unwrap();
    assert!(peak < 100 << 20, "peak resident memory {} MB", peak >> 20);
}

/// Found by the `recording` target's million-case campaign (seed 20261206, case 117069; the
/// file is the case): a chunk record with bytes after its compressed records, and a record
/// among them running past the chunk. The chunk's own reader was given those bytes too, and
/// the overflow above came back. Now it is given the chunk's records and nothing after them.
#[test]
fn issue_36_bytes_after_a_chunks_records_are_not_read_as_its_records() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/findings/recording-bytes-after-a-chunk.mcap");
    let err = first_error(&path);
    assert!(matches!(err, ReadError::Corrupt { .. }), "{err:?}");
}
