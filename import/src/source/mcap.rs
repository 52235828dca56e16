//! MCAP files (ros2 profile: `cdr` channels; `ros1` channels too).
//!
//! Read with the `mcap` crate's sans-io readers fed from a [`File`]: no mmap (this crate forbids
//! `unsafe`) and never the whole file in memory. [`McapFile::for_each`] streams the data section
//! in file order through [`LinearReader`], which holds at most one record and the chunk it is
//! decompressing (zstd, lz4 or none). [`McapFile::topics`] comes from the summary section
//! (channels, statistics, and the message index records for the time spans) when the file has
//! one, else from reading the file through.
//!
//! Only channels whose `message_encoding` is `cdr` ([`Encoding::Cdr`]) or `ros1`
//! ([`Encoding::Ros1`]) are listed and read; the message type is the channel's schema name,
//! normalised to `pkg/Type` (empty when the channel has no schema).

use super::{RawMessage, Source, SourceError, TopicInfo};
use crate::ros::{normalise_type, Encoding};
use crate::ImportError;
use mcap::records::{op, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::sans_io::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// The first bytes of an MCAP file.
pub const MAGIC: &[u8] = &[0x89, b'M', b'C', b'A', b'P', 0x30, b'\r', b'\n'];

/// A record's opcode, body and the bytes read so far -> go on?  ([`McapFile::records`]).
type OnRecord<'a> = dyn FnMut(u8, &[u8], u64) -> Result<bool, SourceError> + 'a;

/// The most bytes handed to the reader per `read` call \[B\]. The reader's buffer grows only as
/// data actually arrives, so a corrupt record length cannot make it allocate more than the file
/// holds.
const READ_PIECE: usize = 1 << 20;

/// The largest record (message, schema, ...) read \[B\]: the reader allocates a record's length
/// before decompressing it, so a corrupt length inside a compressed chunk must be refused, not
/// allocated. 256 MiB is far above any message this crate reads (a radar cloud is kilobytes to
/// a few megabytes).
pub const MAX_RECORD_BYTES: usize = 256 << 20;

/// An MCAP file opened for reading.
#[derive(Debug)]
pub struct McapFile {
    /// The file as errors and [`Source::path`] name it.
    path: PathBuf,
    /// The file read (differs from `path` for a decompressed copy).
    file: PathBuf,
    size: u64,
    /// `file` is a decompressed copy of `path`: offsets in errors are into the decompressed data.
    decompressed: bool,
    /// The first uncompressed chunk whose records overrun it: its offset \[B\] and what is wrong.
    /// No reader is fed that chunk's bytes (see [`McapFile::check_chunks`]); reading stops
    /// there with this error, after everything before it.
    bad_chunk: Option<(u64, String)>,
}

/// A channel as the reader resolved it.
#[derive(Debug)]
struct Chan {
    topic: String,
    msg_type: String,
    /// `None` for encodings this crate does not decode (json, protobuf, ...).
    encoding: Option<Encoding>,
}

impl Chan {
    fn new(topic: &str, schema_name: Option<&str>, message_encoding: &str) -> Chan {
        Chan {
            topic: topic.to_string(),
            msg_type: schema_name.map(normalise_type).unwrap_or_default(),
            encoding: encoding_of(message_encoding),
        }
    }
}

/// `cdr` -> CDR, `ros1` -> ROS 1, anything else -> none.
fn encoding_of(message_encoding: &str) -> Option<Encoding> {
    match message_encoding {
        "cdr" => Some(Encoding::Cdr),
        "ros1" => Some(Encoding::Ros1),
        _ => None,
    }
}

/// Adds a channel's counts to the topic list, merging channels of the same topic and type.
fn add_topic(out: &mut Vec<TopicInfo>, chan: &Chan, count: u64, span: Option<(u64, u64)>) {
    if chan.encoding.is_none() {
        return;
    }
    if let Some(t) = out
        .iter_mut()
        .find(|t| t.topic == chan.topic && t.msg_type == chan.msg_type)
    {
        t.count += count;
        t.span_ns = merge_span(t.span_ns, span);
    } else {
        out.push(TopicInfo {
            topic: chan.topic.clone(),
            msg_type: chan.msg_type.clone(),
            count,
            span_ns: span,
        });
    }
}

/// A log-time span \[ns\]: first and last (none when empty).
pub(crate) type Span = Option<(u64, u64)>;

/// A message handler of [`McapFile::scan`]: channel, log time \[ns\], payload.
type OnMessage<'a, E> = dyn FnMut(&Chan, u64, &[u8]) -> Result<(), E> + 'a;

/// The union of two time spans \[ns\].
pub(crate) fn merge_span(a: Span, b: Span) -> Span {
    match (a, b) {
        (Some((a0, a1)), Some((b0, b1))) => Some((a0.min(b0), a1.max(b1))),
        (x, None) | (None, x) => x,
    }
}

impl McapFile {
    /// Opens `path` and checks its magic.
    pub fn open(path: &Path) -> Result<McapFile, SourceError> {
        Self::open_copy(path, path)
    }

    /// Opens `file`, a decompressed copy of `path`; errors name `path`.
    pub(crate) fn open_copy(file: &Path, path: &Path) -> Result<McapFile, SourceError> {
        let mut f = File::open(file).map_err(|error| SourceError::Io {
            path: path.into(),
            error,
        })?;
        let size = f
            .metadata()
            .map_err(|error| SourceError::Io {
                path: path.into(),
                error,
            })?
            .len();
        let mut head = [0u8; 8];
        let mut n = 0;
        while n < head.len() {
            match f.read(&mut head[n..]) {
                Ok(0) => break,
                Ok(k) => n += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(error) => {
                    return Err(SourceError::Io {
                        path: path.into(),
                        error,
                    })
                }
            }
        }
        if &head[..n] != MAGIC {
            let why = format!("starts with {:02x?}, not the MCAP magic", &head[..n]);
            return Err(if file == path {
                SourceError::UnknownFormat {
                    path: path.into(),
                    why,
                }
            } else {
                SourceError::Corrupt {
                    path: path.into(),
                    at: 0,
                    why: format!("decompressed, it {why}"),
                }
            });
        }
        let mut m = McapFile {
            path: path.into(),
            file: file.into(),
            size,
            decompressed: file != path,
            bad_chunk: None,
        };
        m.bad_chunk = m.check_chunks();
        Ok(m)
    }

    /// The first uncompressed chunk whose records overrun it: its offset \[B\] and why. The
    /// `mcap` crate's reader subtracts an inner record's length from what is left of its chunk
    /// without checking it (a record claiming more than the chunk holds underflows: a panic with
    /// overflow checks, a runaway read without; found by the fuzz target `import_mcap`), so such
    /// a chunk must never reach it. The whole file is walked (`scan` reads a chunk after the data
    /// end too), by record headers only: no chunk is loaded. Other damage (a cut file, an absurd
    /// length) ends the walk without an error here: the readers report it where they meet it,
    /// after delivering what came before.
    fn check_chunks(&self) -> Option<(u64, String)> {
        let file = File::open(&self.file).ok()?;
        find_bad_chunk(&mut Walk::new(file)).ok().flatten()
    }

    /// Hands `reader` the next bytes of `file` it asks for (`need`, at most [`READ_PIECE`]),
    /// counting them in `fed`, but never the bytes of a bad chunk: there, that chunk's error.
    fn feed(
        &self,
        reader: &mut LinearReader,
        file: &mut File,
        need: usize,
        fed: &mut u64,
    ) -> Result<(), SourceError> {
        let mut want = need.clamp(1, READ_PIECE);
        if let Some((start, why)) = &self.bad_chunk {
            if *fed >= *start {
                return Err(self.corrupt(*start, why.clone()));
            }
            want = want.min(usize::try_from(start - *fed).unwrap_or(usize::MAX));
        }
        let buf = reader.insert(want);
        let n = loop {
            match file.read(buf) {
                Ok(n) => break n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(self.io(e)),
            }
        };
        *fed += n as u64;
        reader.notify_read(n);
        Ok(())
    }

    /// Reads the file through a linear reader with `options` (and the record length limit),
    /// giving each record's opcode and body, with the bytes fed so far (where an error shows),
    /// to `on_record` until it returns `false`.
    fn records(
        &self,
        options: LinearReaderOptions,
        on_record: &mut OnRecord<'_>,
    ) -> Result<(), SourceError> {
        let mut file = File::open(&self.file).map_err(|e| self.io(e))?;
        let mut reader =
            LinearReader::new_with_options(options.with_record_length_limit(MAX_RECORD_BYTES));
        let mut fed: u64 = 0;
        while let Some(event) = reader.next_event() {
            match event.map_err(|e| self.mcap_err(fed, &e))? {
                LinearReadEvent::ReadRequest(need) => {
                    self.feed(&mut reader, &mut file, need, &mut fed)?
                }
                LinearReadEvent::Record { opcode, data } => {
                    if !on_record(opcode, data, fed)? {
                        break;
                    }
                }
            }
        }
        Ok(())
    }

    /// File size \[B\].
    pub fn size(&self) -> u64 {
        self.size
    }

    fn io(&self, error: std::io::Error) -> SourceError {
        SourceError::Io {
            path: self.path.clone(),
            error,
        }
    }

    fn corrupt(&self, at: u64, why: impl Into<String>) -> SourceError {
        let mut why = why.into();
        if self.decompressed {
            why.push_str(" (offset into the decompressed file)");
        }
        SourceError::Corrupt {
            path: self.path.clone(),
            at,
            why,
        }
    }

    fn mcap_err(&self, at: u64, e: &mcap::McapError) -> SourceError {
        let why = match e {
            mcap::McapError::UnexpectedEof => {
                "the file ends inside a record (truncated?)".to_string()
            }
            mcap::McapError::RecordTooLarge { opcode, len } => format!(
                "record (opcode {opcode:#04x}) of {len} B, over the {} MiB limit (corrupt?)",
                MAX_RECORD_BYTES >> 20
            ),
            mcap::McapError::UnsupportedCompression(c) => {
                return SourceError::Unsupported {
                    path: self.path.clone(),
                    what: format!("MCAP chunk compression `{c}`"),
                }
            }
            e => e.to_string(),
        };
        self.corrupt(at, why)
    }

    /// Reads the data section in file order, calling `on_channel` for every channel record
    /// (first sighting of each id) and `on_message` for every message whose channel
    /// `wanted` accepts. Errors name the byte offset read up to when the problem showed.
    fn scan<E: From<SourceError>>(
        &self,
        wanted: &dyn Fn(&Chan) -> bool,
        on_channel: &mut dyn FnMut(u16, &Chan) -> Result<(), E>,
        on_message: &mut OnMessage<'_, E>,
    ) -> Result<(), E> {
        let mut file = File::open(&self.file).map_err(|e| self.io(e))?;
        let mut reader = LinearReader::new_with_options(
            LinearReaderOptions::default()
                .with_validate_chunk_crcs(true)
                .with_validate_data_section_crc(true)
                .with_record_length_limit(MAX_RECORD_BYTES),
        );
        let mut schemas: HashMap<u16, String> = HashMap::new();
        // Channel id -> (channel, wanted).
        let mut chans: HashMap<u16, (Chan, bool)> = HashMap::new();
        // Bytes handed to the reader so far: where reading stopped when an error shows.
        let mut fed: u64 = 0;
        let mut past_data_end = false;
        while let Some(event) = reader.next_event() {
            let event = event.map_err(|e| self.mcap_err(fed, &e))?;
            match event {
                LinearReadEvent::ReadRequest(need) => {
                    self.feed(&mut reader, &mut file, need, &mut fed)?
                }
                LinearReadEvent::Record { opcode, data } => {
                    if opcode == op::DATA_END {
                        // The summary repeats schemas and channels; read on only to check the
                        // footer and end magic.
                        past_data_end = true;
                        continue;
                    }
                    if past_data_end || !matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE) {
                        continue;
                    }
                    // The mcap crate sizes strings and maps by their length prefixes before
                    // reading them: a corrupt prefix must not become a 4 GiB allocation.
                    check_prefixes(opcode, data).map_err(|why| self.corrupt(fed, why))?;
                    let record =
                        mcap::parse_record(opcode, data).map_err(|e| self.mcap_err(fed, &e))?;
                    match record {
                        Record::Schema { header, .. } => {
                            schemas.insert(header.id, header.name);
                        }
                        Record::Channel(c) => {
                            if chans.contains_key(&c.id) {
                                continue;
                            }
                            let schema = match c.schema_id {
                                0 => None,
                                id => Some(schemas.get(&id).ok_or_else(|| {
                                    self.corrupt(
                                        fed,
                                        format!(
                                            "channel {} (`{}`) refers to schema {id}, not \
                                             defined before it",
                                            c.id, c.topic
                                        ),
                                    )
                                })?),
                            };
                            let chan = Chan::new(
                                &c.topic,
                                schema.map(String::as_str),
                                &c.message_encoding,
                            );
                            on_channel(c.id, &chan)?;
                            let w = wanted(&chan);
                            chans.insert(c.id, (chan, w));
                        }
                        Record::Message { header, data } => {
                            let (chan, w) = chans.get(&header.channel_id).ok_or_else(|| {
                                self.corrupt(
                                    fed,
                                    format!(
                                        "message (sequence {}) on channel {}, not defined \
                                         before it",
                                        header.sequence, header.channel_id
                                    ),
                                )
                            })?;
                            if *w {
                                on_message(chan, header.log_time, &data)?;
                            }
                        }
                        _ => {}
                    }
                }
            }
        }
        Ok(())
    }

    /// The summary section, if the file has one that reads cleanly.
    fn summary(&self) -> Option<mcap::Summary> {
        let mut file = File::open(&self.file).ok()?;
        let limit = usize::try_from(self.size).unwrap_or(usize::MAX);
        let mut reader = SummaryReader::new_with_options(
            SummaryReaderOptions::default()
                .with_file_size(self.size)
                .with_record_length_limit(limit),
        );
        while let Some(event) = reader.next_event() {
            match event.ok()? {
                SummaryReadEvent::ReadRequest(need) => {
                    let n = file.read(reader.insert(need.min(READ_PIECE))).ok()?;
                    reader.notify_read(n);
                }
                SummaryReadEvent::SeekRequest(to) => {
                    let pos = file.seek(to).ok()?;
                    reader.notify_seeked(pos);
                }
            }
        }
        reader.finish()
    }

    /// Topics from the summary: counts from the statistics, spans from the message indexes.
    /// `None` when anything needed is missing or disagrees (then the file is read through).
    fn topics_from_summary(&self) -> Option<Vec<TopicInfo>> {
        let summary = self.summary()?;
        let stats = summary.stats.as_ref()?;
        let mut file = File::open(&self.file).ok()?;
        // Channel id -> (indexed messages, span).
        let mut indexed: BTreeMap<u16, (u64, Option<(u64, u64)>)> = BTreeMap::new();
        for chunk in &summary.chunk_indexes {
            for (&channel, &offset) in &chunk.message_index_offsets {
                let (n, span) = self.read_message_index(&mut file, channel, offset)?;
                let e = indexed.entry(channel).or_insert((0, None));
                e.0 += n;
                e.1 = merge_span(e.1, span);
            }
        }
        let mut out = Vec::new();
        for (id, channel) in summary.channels.iter().collect::<BTreeMap<_, _>>() {
            let count = stats.channel_message_counts.get(id).copied().unwrap_or(0);
            let (n, span) = indexed.get(id).copied().unwrap_or((0, None));
            if n != count {
                // Messages outside chunks, or an index that disagrees: read it through.
                return None;
            }
            let chan = Chan::new(
                &channel.topic,
                channel.schema.as_ref().map(|s| s.name.as_str()),
                &channel.message_encoding,
            );
            add_topic(&mut out, &chan, count, span);
        }
        Some(out)
    }

    /// One message index record: (messages, their log-time span).
    fn read_message_index(
        &self,
        file: &mut File,
        channel: u16,
        offset: u64,
    ) -> Option<(u64, Option<(u64, u64)>)> {
        file.seek(SeekFrom::Start(offset)).ok()?;
        let mut head = [0u8; 9];
        file.read_exact(&mut head).ok()?;
        let len = u64::from_le_bytes(head[1..].try_into().ok()?);
        if head[0] != op::MESSAGE_INDEX || len > self.size.saturating_sub(offset.saturating_add(9))
        {
            return None;
        }
        let mut body = vec![0u8; usize::try_from(len).ok()?];
        file.read_exact(&mut body).ok()?;
        match mcap::parse_record(op::MESSAGE_INDEX, &body).ok()? {
            Record::MessageIndex(ix) if ix.channel_id == channel => {
                let span = ix
                    .records
                    .iter()
                    .fold(None, |s, e| merge_span(s, Some((e.log_time, e.log_time))));
                Some((ix.records.len() as u64, span))
            }
            _ => None,
        }
    }

    fn topics_by_reading(&self) -> Result<Vec<TopicInfo>, SourceError> {
        // Channels in order of appearance, and per (topic, type) the count and span.
        let mut seen: Vec<Chan> = Vec::new();
        let mut counts: HashMap<(String, String), (u64, Span)> = HashMap::new();
        self.scan::<SourceError>(
            &|c| c.encoding.is_some(),
            &mut |_, c| {
                seen.push(Chan {
                    topic: c.topic.clone(),
                    msg_type: c.msg_type.clone(),
                    encoding: c.encoding,
                });
                Ok(())
            },
            &mut |c, t, _| {
                let e = counts
                    .entry((c.topic.clone(), c.msg_type.clone()))
                    .or_insert((0, None));
                e.0 += 1;
                e.1 = merge_span(e.1, Some((t, t)));
                Ok(())
            },
        )?;
        let mut out = Vec::new();
        for chan in &seen {
            // Take each (topic, type) once: the counts are already merged.
            if let Some((count, span)) = counts.remove(&(chan.topic.clone(), chan.msg_type.clone()))
            {
                add_topic(&mut out, chan, count, span);
            } else {
                add_topic(&mut out, chan, 0, None);
            }
        }
        Ok(out)
    }
}

impl McapFile {
    /// Every metadata record of the data section, in file order.
    fn metadata_records(&self) -> Result<Vec<super::MetadataRecord>, SourceError> {
        let mut out = Vec::new();
        self.records(LinearReaderOptions::default(), &mut |opcode, data, fed| {
            if opcode == op::DATA_END {
                return Ok(false);
            }
            if opcode == op::METADATA {
                check_prefixes(opcode, data).map_err(|why| self.corrupt(fed, why))?;
                if let Record::Metadata(m) =
                    mcap::parse_record(opcode, data).map_err(|e| self.mcap_err(fed, &e))?
                {
                    out.push((m.name, m.metadata));
                }
            }
            Ok(true)
        })?;
        Ok(out)
    }
}

impl Source for McapFile {
    fn path(&self) -> &Path {
        &self.path
    }

    fn metadata(&mut self) -> Result<Vec<super::MetadataRecord>, SourceError> {
        self.metadata_records()
    }

    /// From the summary section when present and consistent, else by reading the file through.
    fn topics(&mut self) -> Result<Vec<TopicInfo>, SourceError> {
        match self.topics_from_summary() {
            Some(t) => Ok(t),
            None => self.topics_by_reading(),
        }
    }

    /// Messages in file order. Asking for a topic whose channel has an encoding other than `cdr`
    /// or `ros1` is [`SourceError::Unsupported`]; with `topics` empty such channels are skipped.
    fn for_each(
        &mut self,
        topics: &[&str],
        f: &mut dyn FnMut(RawMessage<'_>) -> Result<(), ImportError>,
    ) -> Result<(), ImportError> {
        let mut index: HashMap<String, u64> = HashMap::new();
        let path = self.path.clone();
        let wanted = |c: &Chan| {
            c.encoding.is_some() && (topics.is_empty() || topics.contains(&c.topic.as_str()))
        };
        self.scan(
            &wanted,
            &mut |_, c| {
                if c.encoding.is_none() && topics.contains(&c.topic.as_str()) {
                    return Err(SourceError::Unsupported {
                        path: path.clone(),
                        what: format!("topic `{}`: message encoding is not cdr or ros1", c.topic),
                    }
                    .into());
                }
                Ok(())
            },
            &mut |c, log_time_ns, data| {
                let i = match index.get_mut(&c.topic) {
                    Some(i) => {
                        *i += 1;
                        *i
                    }
                    None => {
                        index.insert(c.topic.clone(), 0);
                        0
                    }
                };
                let Some(encoding) = c.encoding else {
                    return Ok(());
                };
                f(RawMessage {
                    topic: &c.topic,
                    msg_type: &c.msg_type,
                    log_time_ns,
                    index: i,
                    data,
                    encoding,
                })
            },
        )
    }
}

/// Reads a file by offset through a buffer: record headers are small and close together.
struct Walk<R> {
    r: std::io::BufReader<R>,
    /// Where `r` stands \[B\].
    at: u64,
}

impl<R: Read + Seek> Walk<R> {
    fn new(r: R) -> Walk<R> {
        Walk {
            r: std::io::BufReader::new(r),
            at: 0,
        }
    }

    /// `buf.len()` bytes at `pos`; `false` where the file ends first.
    fn read_at(&mut self, pos: u64, buf: &mut [u8]) -> std::io::Result<bool> {
        // Forward within the buffer where it can; anywhere else, a seek.
        match pos.checked_sub(self.at).and_then(|d| i64::try_from(d).ok()) {
            Some(d) => self.r.seek_relative(d)?,
            None => {
                self.r.seek(SeekFrom::Start(pos))?;
            }
        }
        self.at = pos;
        let mut n = 0;
        while n < buf.len() {
            match self.r.read(&mut buf[n..]) {
                Ok(0) => break,
                Ok(k) => n += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        self.at += n as u64;
        Ok(n == buf.len())
    }
}

/// The first chunk (offset \[B\], why) among the top-level records after the magic that
/// [`check_chunk`] refuses; `None` where the walk reaches the footer or the file's end first.
fn find_bad_chunk<R: Read + Seek>(w: &mut Walk<R>) -> std::io::Result<Option<(u64, String)>> {
    let mut pos = MAGIC.len() as u64;
    let mut head = [0u8; 9];
    while w.read_at(pos, &mut head)? {
        let len = u64::from_le_bytes(head[1..].try_into().expect("8 bytes"));
        match head[0] {
            op::CHUNK => {
                if let Err(why) = check_chunk(w, pos + 9, len)? {
                    return Ok(Some((pos, why)));
                }
            }
            op::FOOTER => break,
            _ => {}
        }
        match pos.checked_add(len).and_then(|p| p.checked_add(9)) {
            Some(p) => pos = p,
            None => break,
        }
    }
    Ok(None)
}

/// Checks an uncompressed chunk whose body (`len` B) starts at `start`: each record inside
/// (opcode, u64 length, body) must fit in what the chunk's records length leaves, as the
/// `mcap` reader counts it down. The header (start and end time, uncompressed size, CRC,
/// compression, records length) is read as that reader reads it. Only what the file holds is
/// checked, so a cut file is not refused here (the reader reports the cut); whatever the reader
/// itself refuses before counting down (a header longer than the chunk, records longer than it,
/// a record over the length limit) is left to it; compressed chunks are left to the
/// decompressor's own checks.
fn check_chunk<R: Read + Seek>(
    w: &mut Walk<R>,
    start: u64,
    len: u64,
) -> std::io::Result<Result<(), String>> {
    let mut head = [0u8; 40];
    if !w.read_at(start, &mut head)? {
        return Ok(Ok(()));
    }
    let comp_len = u32::from_le_bytes(head[28..32].try_into().expect("4 bytes"));
    if comp_len > 0 || len < 40 {
        return Ok(Ok(()));
    }
    let mut left = u64::from_le_bytes(head[32..40].try_into().expect("8 bytes"));
    if left > len - 40 {
        return Ok(Ok(()));
    }
    let mut k = 40u64;
    let mut rec = [0u8; 9];
    while left > 0 && w.read_at(start + k, &mut rec)? {
        let n = u64::from_le_bytes(rec[1..].try_into().expect("8 bytes"));
        if n > MAX_RECORD_BYTES as u64 {
            break;
        }
        if n + 9 > left {
            return Ok(Err(format!(
                "chunk: its record at byte {k} (opcode {:#04x}) claims {n} B, {} B are left",
                rec[0],
                left.saturating_sub(9)
            )));
        }
        left -= n + 9;
        k += n + 9;
    }
    Ok(Ok(()))
}

/// Checks that every length prefix of a schema, channel or metadata record fits the record:
/// schema `u16 id, string name, string encoding`; channel `u16 id, u16 schema id, string topic,
/// string message encoding, map metadata`; metadata `string name, map metadata` (a string or map
/// is `u32 len` + that many bytes; a map's entries are key/value string pairs within it). The
/// schema's data length the crate checks itself; message records have no prefix before their data.
fn check_prefixes(opcode: u8, body: &[u8]) -> Result<(), String> {
    let (what, fixed, prefixed): (&str, usize, &[&str]) = match opcode {
        op::SCHEMA => ("schema", 2, &["name", "encoding"]),
        op::CHANNEL => ("channel", 4, &["topic", "message encoding", "metadata"]),
        op::METADATA => ("metadata", 0, &["name", "metadata"]),
        _ => return Ok(()),
    };
    let cut = |at: usize, n: u64, field: &str| {
        format!(
            "{what} record: its {field} needs {n} B at byte {at}, the record has {} B",
            body.len()
        )
    };
    if body.len() < fixed {
        return Err(cut(0, fixed as u64, "ids"));
    }
    let mut at = fixed;
    for field in prefixed {
        let len = body
            .get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .ok_or_else(|| cut(at, 4, &format!("{field} length")))?;
        if u64::from(len) > (body.len() - at - 4) as u64 {
            return Err(cut(at + 4, u64::from(len), field));
        }
        if *field == "metadata" {
            // A map: its byte length, then key and value strings, each length-prefixed, all
            // within the map.
            let end = at + 4 + len as usize;
            let mut k = at + 4;
            let mut strings = 0usize;
            while k < end {
                strings += 1;
                let n = body
                    .get(k..k + 4)
                    .filter(|_| k + 4 <= end)
                    .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                    .ok_or_else(|| cut(k, 4, "metadata entry length"))?;
                if u64::from(n) > (end - k - 4) as u64 {
                    return Err(cut(k + 4, u64::from(n), "metadata entry"));
                }
                k += 4 + n as usize;
            }
            if strings % 2 == 1 {
                // The `mcap` crate reads the value's length past the map's end (a key without
                // a value made it allocate gigabytes: found by the fuzz target).
                return Err(cut(end, 4, "metadata value length (a key without a value)"));
            }
        }
        at += 4 + len as usize;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metadata_entries_beyond_their_map_are_refused() {
        // A channel whose metadata map (8 B) holds a key claiming 0xFA000000 bytes: the input the
        // fuzzer found (the mcap crate would allocate 4 GB for it).
        let mut c = vec![1, 0, 0, 0];
        for s in ["/a", "cdr"] {
            c.extend((s.len() as u32).to_le_bytes());
            c.extend(s.as_bytes());
        }
        c.extend(8u32.to_le_bytes());
        c.extend(0xfa00_0000u32.to_le_bytes());
        c.extend([0u8; 4]);
        let e = check_prefixes(op::CHANNEL, &c).unwrap_err();
        assert!(e.contains("metadata entry"), "{e}");
        // A well-formed entry passes.
        let mut ok = c[..c.len() - 12].to_vec();
        ok.extend(10u32.to_le_bytes());
        ok.extend(1u32.to_le_bytes());
        ok.extend(b"k");
        ok.extend(1u32.to_le_bytes());
        ok.extend(b"v");
        assert_eq!(check_prefixes(op::CHANNEL, &ok), Ok(()));
    }

    #[test]
    fn length_prefixes_beyond_the_record_are_refused() {
        // A channel: id 1, schema 0, topic "/a", encoding "cdr", empty metadata.
        let mut ok = vec![1, 0, 0, 0];
        for s in ["/a", "cdr"] {
            ok.extend((s.len() as u32).to_le_bytes());
            ok.extend(s.as_bytes());
        }
        ok.extend(0u32.to_le_bytes());
        assert_eq!(check_prefixes(op::CHANNEL, &ok), Ok(()));
        let mut bad = ok.clone();
        bad[4..8].copy_from_slice(&0xfb00_0000u32.to_le_bytes());
        let e = check_prefixes(op::CHANNEL, &bad).unwrap_err();
        assert!(
            e.contains("channel record: its topic needs 4211081216 B"),
            "{e}"
        );
        assert!(check_prefixes(op::CHANNEL, &ok[..ok.len() - 2]).is_err());
        assert!(check_prefixes(op::SCHEMA, &[1]).is_err());
    }

    #[test]
    fn a_metadata_key_without_a_value_is_refused() {
        // Name "", a 4-byte map holding one empty key and no value (the fuzzer's input had the
        // value's length read from beyond the map: a 2.3 GB allocation).
        let mut body = 0u32.to_le_bytes().to_vec();
        body.extend(4u32.to_le_bytes());
        body.extend(0u32.to_le_bytes());
        body.extend([0, 2, 0, 0xf6, 0xff, 0xff, 0xff, 0x7f]);
        let e = check_prefixes(op::METADATA, &body).unwrap_err();
        assert!(e.contains("a key without a value"), "{e}");
        // Key and value, both empty: fine.
        let mut body = 0u32.to_le_bytes().to_vec();
        body.extend(8u32.to_le_bytes());
        body.extend([0u8; 8]);
        assert_eq!(check_prefixes(op::METADATA, &body), Ok(()));
    }

    #[test]
    fn a_chunk_record_beyond_its_chunk_is_an_error_not_an_underflow() {
        // The fuzz target's input (after the magic it prepends): an uncompressed chunk whose
        // inner record claims 0x07ffffffffffffff bytes.
        let tail: &[u8] = &[
            6, 0, 0, 110, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 255, 255, 255, 255, 255, 255, 255, 7, 0, 0,
            0, 0, 0, 0, 254, 253, 255, 255, 255, 255, 255, 255, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0,
            0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2,
        ];
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.mcap");
        let mut bytes = b"\x89MCAP0\r\n".to_vec();
        bytes.extend(tail);
        std::fs::write(&p, bytes).unwrap();
        // The file opens (a cut or damaged file still gives what comes before the damage); the
        // chunk's bytes never reach the reader, and reading stops at it with its offset.
        let mut f = McapFile::open(&p).unwrap();
        for r in [f.metadata().map(|_| ()), f.topics().map(|_| ())] {
            match r {
                Err(SourceError::Corrupt { at: 8, why, .. }) => {
                    assert!(why.contains("claims"), "{why}")
                }
                r => panic!("expected the chunk's error at byte 8, got {r:?}"),
            }
        }
        // The second one: the same kind of chunk after a data-end record.
        let tail: &[u8] = &[
            15, 7, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 118, 0, 6, 0, 64, 0, 0, 0, 0, 0, 0, 0, 0, 0,
            0, 0, 0, 0, 0, 116, 182, 65, 239, 42, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
            0, 0, 0, 6, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
            0, 0, 0, 0, 0, 10,
        ];
        let mut bytes = b"\x89MCAP0\r\n".to_vec();
        bytes.extend(tail);
        std::fs::write(&p, bytes).unwrap();
        let r = McapFile::open(&p).and_then(|mut f| f.topics());
        assert!(r.is_err(), "{r:?}");
        // A chunk whose one record overruns it, built field by field.
        let mut chunk = vec![0u8; 28];
        chunk.extend(0u32.to_le_bytes()); // no compression
        chunk.extend(12u64.to_le_bytes()); // records: 12 B
        chunk.push(op::MESSAGE);
        chunk.extend(100u64.to_le_bytes()); // claims 100 B
        chunk.extend([0u8; 3]);
        // The chunk's bytes as the file holds them (cut or not), and its length as its header
        // claims.
        let n = chunk.len();
        let check = |bytes: &[u8]| {
            let mut w = Walk::new(std::io::Cursor::new(bytes.to_vec()));
            check_chunk(&mut w, 0, n as u64).unwrap()
        };
        let e = check(&chunk).unwrap_err();
        assert!(e.contains("claims 100 B, 3 B are left"), "{e}");
        // Cut inside the record's body: still refused (its header alone says it overruns).
        assert!(check(&chunk[..n - 2]).is_err());
        // Cut inside its header: nothing to check (the reader reports the cut).
        assert_eq!(check(&chunk[..n - 5]), Ok(()));
        // The same record fitting is fine, and so is a cut inside it.
        chunk[n - 11..n - 3].copy_from_slice(&3u64.to_le_bytes());
        assert_eq!(check(&chunk), Ok(()));
        assert_eq!(check(&chunk[..n - 1]), Ok(()));
    }

    #[test]
    fn a_fuzzer_found_input_is_an_error_not_a_4_gib_allocation() {
        // After the magic: a channel record (0x04) whose topic claims 0xff56f9fb bytes.
        let tail = b"\x04\x12\0\0\0\0\0\0\0\x04\0\0\0\0\0\0\xfb\xf9V\xff\0\0\0\x12\0\0\0\0\0\0";
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.mcap");
        let mut bytes = b"\x89MCAP0\r\n".to_vec();
        bytes.extend(tail);
        std::fs::write(&p, bytes).unwrap();
        let r = McapFile::open(&p).and_then(|mut f| f.topics());
        assert!(matches!(r, Err(SourceError::Corrupt { .. })), "{r:?}");
    }
}
