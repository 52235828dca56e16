//! ROS 1 bags (format 2.0), read as a stream.
//!
//! The layout (<http://wiki.ros.org/Bags/Format/2.0>): the magic `#ROSBAG V2.0\n`, then records.
//! A record is a `u32` header length, the header (fields, each a `u32` length then
//! `name=value`; the `op` field says what the record is), a `u32` data length and the data. All
//! integers are little-endian; a `time` is `u32 sec, u32 nsec`.
//!
//! | op | record | header fields | data |
//! | --- | --- | --- | --- |
//! | `0x03` | bag header | `index_pos`, `conn_count`, `chunk_count` | padding (to 4096 B) |
//! | `0x05` | chunk | `compression` (`none`, `bz2`, `lz4`), `size` (uncompressed) | records |
//! | `0x07` | connection | `conn`, `topic` | a connection header: `type`, `md5sum`, ... |
//! | `0x02` | message data | `conn`, `time` | the serialised message |
//! | `0x04` | index data | `ver`, `conn`, `count` | `count` × (`time`, `u32` offset) |
//! | `0x06` | chunk info | `ver`, `chunk_pos`, `start_time`, `end_time`, `count` | `count` × (`u32` conn, `u32` count) |
//!
//! Chunks (each followed by its index data records) fill the file up to `index_pos`; there the
//! index section holds every connection record, then one chunk info per chunk. A bag whose
//! recording never finished has `index_pos` 0 and no index section.
//!
//! [`Bag1`] reads with a buffered reader and holds at most one decompressed chunk in memory.
//! Every length is checked against what is left of the file before anything is allocated.

use super::{RawMessage, Source, SourceError, TopicInfo};
use crate::ros::{normalise_type, Encoding};
use std::collections::{HashMap, HashSet};
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// The first bytes of a ROS 1 bag.
pub const MAGIC: &[u8] = b"#ROSBAG V2.0\n";

const OP_MSG_DATA: u8 = 0x02;
const OP_BAG_HEADER: u8 = 0x03;
const OP_INDEX_DATA: u8 = 0x04;
const OP_CHUNK: u8 = 0x05;
const OP_CHUNK_INFO: u8 = 0x06;
const OP_CONNECTION: u8 = 0x07;

/// Most bytes reserved ahead for a decompressed chunk (it grows past this only as data arrives).
const RESERVE_MAX: usize = 16 << 20;

/// A ROS 1 bag opened for reading.
#[derive(Debug)]
pub struct Bag1 {
    path: PathBuf,
    /// File size \[B\] when opened.
    file_len: u64,
    /// Offset of the first record after the bag header \[B\].
    data_start: u64,
    /// Offset of the index section \[B\]; 0 when the bag is not indexed.
    index_pos: u64,
    /// Connections the bag header announces.
    conn_count: u32,
    /// Chunks the bag header announces.
    chunk_count: u32,
}

impl Bag1 {
    /// Opens `path`, checks the magic and reads the bag header record.
    pub fn open(path: &Path) -> Result<Bag1, SourceError> {
        let mut sc = Scanner::open(path)?;
        let mut magic = [0u8; 13];
        let n = sc.read_up_to(&mut magic)?;
        if &magic[..n] != MAGIC {
            return Err(SourceError::UnknownFormat {
                path: path.into(),
                why: "no `#ROSBAG V2.0` magic".into(),
            });
        }
        let file_len = sc.len;
        let rec = sc
            .next_record(file_len)?
            .ok_or_else(|| corrupt(path, sc.pos, "no bag header record after the magic"))?;
        let head = Fields::parse(&rec.header, rec.at, path)?;
        if head.op()? != OP_BAG_HEADER {
            return Err(corrupt(
                path,
                rec.at,
                "the first record is not the bag header",
            ));
        }
        sc.skip_data(&rec)?;
        let bag = Bag1 {
            path: path.into(),
            file_len,
            data_start: sc.pos,
            index_pos: head.u64("index_pos")?,
            conn_count: head.u32("conn_count")?,
            chunk_count: head.u32("chunk_count")?,
        };
        if bag.index_pos != 0 && bag.index_pos < bag.data_start {
            return Err(corrupt(
                path,
                rec.at,
                format!("index_pos {} points into the bag header", bag.index_pos),
            ));
        }
        Ok(bag)
    }

    /// Whether the bag header points at an index section.
    pub fn is_indexed(&self) -> bool {
        self.index_pos != 0
    }

    /// Where the chunks end \[B\]: the index section, or the end of the file when unindexed.
    fn data_end(&self) -> u64 {
        if self.is_indexed() {
            self.index_pos
        } else {
            self.file_len
        }
    }

    /// Reads every record from the first chunk to the index section in file order, calling `f` on
    /// each message with its topic's running index; `cat` learns the connections met on the way.
    /// Chunks whose offsets are in `skip` are stepped over without being read or decompressed.
    fn walk<E: From<SourceError>>(
        &self,
        cat: &mut Catalogue,
        skip: &HashSet<u64>,
        f: &mut dyn FnMut(RawMessage<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        let mut sc = Scanner::open(&self.path)?;
        sc.seek(self.data_start)?;
        let end = self.data_end();
        while let Some(rec) = sc.next_record(end)? {
            let fields = Fields::parse(&rec.header, rec.at, &self.path)?;
            match fields.op()? {
                OP_CHUNK if skip.contains(&rec.at) => sc.skip_data(&rec)?,
                OP_CHUNK => {
                    let chunk = sc.read_chunk(&rec, &fields)?;
                    walk_chunk(&chunk, &self.path, cat, f)?;
                }
                OP_CONNECTION => {
                    let data = sc.read_data(&rec)?;
                    cat.add_connection(&fields, &data, &self.path)?;
                }
                OP_MSG_DATA => {
                    let data = sc.read_data(&rec)?;
                    cat.message(&fields, &data, rec.at, &self.path, f)?;
                }
                OP_INDEX_DATA | OP_CHUNK_INFO => sc.skip_data(&rec)?,
                op => {
                    return Err(corrupt(
                        &self.path,
                        rec.at,
                        format!("unexpected record op {op:#04x} among the chunks"),
                    )
                    .into())
                }
            }
        }
        Ok(())
    }

    /// The topics from the index section and the index data records after each chunk, without
    /// decompressing anything. Fails when the index is missing, incomplete or inconsistent.
    fn topics_from_index(&self) -> Result<Vec<TopicInfo>, SourceError> {
        if !self.is_indexed() {
            return Err(corrupt(&self.path, 0, "not indexed"));
        }
        let mut sc = Scanner::open(&self.path)?;
        let (mut cat, chunks) = self.read_index(&mut sc)?;
        for chunk in &chunks {
            self.read_chunk_index(&mut sc, chunk, &mut cat)?;
        }
        Ok(cat.topics())
    }

    /// The index section: its connection records and chunk infos.
    fn read_index(&self, sc: &mut Scanner) -> Result<(Catalogue, Vec<ChunkInfo>), SourceError> {
        sc.seek(self.index_pos)?;
        let mut cat = Catalogue::default();
        let mut chunks = Vec::new();
        while let Some(rec) = sc.next_record(self.file_len)? {
            let fields = Fields::parse(&rec.header, rec.at, &self.path)?;
            let data = sc.read_data(&rec)?;
            match fields.op()? {
                OP_CONNECTION => cat.add_connection(&fields, &data, &self.path)?,
                OP_CHUNK_INFO => chunks.push(ChunkInfo::parse(&fields, &data, rec.at, &self.path)?),
                op => {
                    return Err(corrupt(
                        &self.path,
                        rec.at,
                        format!("unexpected record op {op:#04x} in the index"),
                    ))
                }
            }
        }
        if cat.conns.len() != self.conn_count as usize || chunks.len() != self.chunk_count as usize
        {
            return Err(corrupt(
                &self.path,
                self.index_pos,
                format!(
                    "index holds {} connections and {} chunk infos, the bag header says {} and {}",
                    cat.conns.len(),
                    chunks.len(),
                    self.conn_count,
                    self.chunk_count
                ),
            ));
        }
        Ok((cat, chunks))
    }

    /// Skips the chunk at `info.pos` and reads the index data records after it into `cat`,
    /// checking them against the chunk info's counts.
    fn read_chunk_index(
        &self,
        sc: &mut Scanner,
        info: &ChunkInfo,
        cat: &mut Catalogue,
    ) -> Result<(), SourceError> {
        if info.pos < self.data_start || info.pos >= self.index_pos {
            return Err(corrupt(
                &self.path,
                info.at,
                format!("chunk_pos {} is outside the chunks", info.pos),
            ));
        }
        sc.seek(info.pos)?;
        let rec = sc
            .next_record(self.index_pos)?
            .ok_or_else(|| corrupt(&self.path, info.pos, "no chunk at chunk_pos"))?;
        if Fields::parse(&rec.header, rec.at, &self.path)?.op()? != OP_CHUNK {
            return Err(corrupt(
                &self.path,
                info.pos,
                "chunk_pos does not point at a chunk",
            ));
        }
        sc.skip_data(&rec)?;
        let mut seen: Vec<(u32, u32)> = Vec::new();
        while let Some(rec) = sc.next_record(self.index_pos)? {
            let fields = Fields::parse(&rec.header, rec.at, &self.path)?;
            if fields.op()? != OP_INDEX_DATA {
                break;
            }
            let data = sc.read_data(&rec)?;
            let conn = fields.u32("conn")?;
            let times = index_times(&fields, &data, rec.at, &self.path)?;
            seen.push((conn, times.len() as u32));
            cat.indexed(conn, &times, rec.at, &self.path)?;
        }
        seen.sort_unstable();
        let mut declared = info.counts.clone();
        declared.sort_unstable();
        if seen != declared {
            return Err(corrupt(
                &self.path,
                info.pos,
                "the chunk's index data records disagree with its chunk info",
            ));
        }
        Ok(())
    }

    /// The topics, by reading every chunk.
    fn topics_by_scan(&self) -> Result<Vec<TopicInfo>, SourceError> {
        let mut cat = Catalogue::default();
        self.walk::<SourceError>(&mut cat, &HashSet::new(), &mut |_| Ok(()))?;
        Ok(cat.topics())
    }

    /// The catalogue of connections from the index and the offsets of the chunks that hold no
    /// message of `topics` (the index's chunk infos say which connections each chunk holds).
    /// `None` when the bag has no usable index: then every chunk is read.
    fn chunks_without(&self, topics: &[&str]) -> Option<(Catalogue, HashSet<u64>)> {
        if !self.is_indexed() || topics.is_empty() {
            return None;
        }
        let mut sc = Scanner::open(&self.path).ok()?;
        let (cat, chunks) = self.read_index(&mut sc).ok()?;
        let wanted: HashSet<u32> = cat
            .conns
            .iter()
            .filter(|(_, &id)| topics.contains(&cat.topics[id].topic.as_str()))
            .map(|(&conn, _)| conn)
            .collect();
        let skip = chunks
            .iter()
            .filter(|c| !c.counts.iter().any(|(conn, _)| wanted.contains(conn)))
            .map(|c| c.pos)
            .collect();
        Some((cat, skip))
    }
}

impl Source for Bag1 {
    fn path(&self) -> &Path {
        &self.path
    }

    /// From the index when the bag has a usable one; else by reading every chunk.
    fn topics(&mut self) -> Result<Vec<TopicInfo>, SourceError> {
        self.topics_from_index().or_else(|_| self.topics_by_scan())
    }

    fn for_each(
        &mut self,
        topics: &[&str],
        f: &mut dyn FnMut(RawMessage<'_>) -> Result<(), crate::ImportError>,
    ) -> Result<(), crate::ImportError> {
        // Chunks holding none of `topics` are skipped: a bag with camera images beside the radar
        // is read at the speed of its radar and IMU data.
        let (mut cat, skip) = self.chunks_without(topics).unwrap_or_default();
        self.walk(&mut cat, &skip, &mut |m: RawMessage<'_>| {
            if topics.is_empty() || topics.contains(&m.topic) {
                f(m)
            } else {
                Ok(())
            }
        })
    }
}

fn corrupt(path: &Path, at: u64, why: impl Into<String>) -> SourceError {
    SourceError::Corrupt {
        path: path.into(),
        at,
        why: why.into(),
    }
}

/// Bag time (`u32 sec, u32 nsec`) \[ns\].
fn time_ns(b: [u8; 8]) -> u64 {
    let sec = u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as u64;
    let nsec = u32::from_le_bytes([b[4], b[5], b[6], b[7]]) as u64;
    sec * 1_000_000_000 + nsec
}

/// The fields of one record header (or of a connection header), in order.
struct Fields<'a> {
    path: &'a Path,
    /// Offset of the record \[B\], for errors.
    at: u64,
    list: Vec<(&'a [u8], &'a [u8])>,
}

impl<'a> Fields<'a> {
    /// Splits `buf` into `name=value` fields.
    fn parse(buf: &'a [u8], at: u64, path: &'a Path) -> Result<Fields<'a>, SourceError> {
        let mut list = Vec::new();
        let mut rest = buf;
        while !rest.is_empty() {
            let (len, tail) = split_u32(rest)
                .ok_or_else(|| corrupt(path, at, "a header field's length is cut short"))?;
            if len as usize > tail.len() {
                return Err(corrupt(
                    path,
                    at,
                    format!("a header field claims {len} B, {} B left", tail.len()),
                ));
            }
            let (field, tail) = tail.split_at(len as usize);
            let eq = field
                .iter()
                .position(|&b| b == b'=')
                .ok_or_else(|| corrupt(path, at, "a header field without `=`"))?;
            list.push((&field[..eq], &field[eq + 1..]));
            rest = tail;
        }
        Ok(Fields { path, at, list })
    }

    fn get(&self, name: &str) -> Option<&'a [u8]> {
        self.list
            .iter()
            .find(|(n, _)| *n == name.as_bytes())
            .map(|(_, v)| *v)
    }

    /// The value of `name`, exactly `N` bytes long.
    fn fixed<const N: usize>(&self, name: &str) -> Result<[u8; N], SourceError> {
        let v = self.get(name).ok_or_else(|| self.missing(name))?;
        v.try_into().map_err(|_| {
            corrupt(
                self.path,
                self.at,
                format!("header field `{name}` is {} B, not {N}", v.len()),
            )
        })
    }

    fn missing(&self, name: &str) -> SourceError {
        corrupt(
            self.path,
            self.at,
            format!("record header lacks the `{name}` field"),
        )
    }

    fn op(&self) -> Result<u8, SourceError> {
        Ok(self.fixed::<1>("op")?[0])
    }

    fn u32(&self, name: &str) -> Result<u32, SourceError> {
        Ok(u32::from_le_bytes(self.fixed(name)?))
    }

    fn u64(&self, name: &str) -> Result<u64, SourceError> {
        Ok(u64::from_le_bytes(self.fixed(name)?))
    }

    /// A `time` field \[ns\].
    fn time_ns(&self, name: &str) -> Result<u64, SourceError> {
        Ok(time_ns(self.fixed(name)?))
    }

    fn string(&self, name: &str) -> Result<&'a str, SourceError> {
        let v = self.get(name).ok_or_else(|| self.missing(name))?;
        std::str::from_utf8(v).map_err(|_| {
            corrupt(
                self.path,
                self.at,
                format!("header field `{name}` is not UTF-8"),
            )
        })
    }
}

fn split_u32(b: &[u8]) -> Option<(u32, &[u8])> {
    let (head, tail) = b.split_first_chunk::<4>()?;
    Some((u32::from_le_bytes(*head), tail))
}

/// A chunk info record of the index section.
#[derive(Debug)]
struct ChunkInfo {
    /// Offset of the chunk info record \[B\].
    at: u64,
    /// Offset of the chunk \[B\].
    pos: u64,
    /// Messages per connection: (conn, count).
    counts: Vec<(u32, u32)>,
}

impl ChunkInfo {
    fn parse(
        fields: &Fields<'_>,
        data: &[u8],
        at: u64,
        path: &Path,
    ) -> Result<ChunkInfo, SourceError> {
        let count = fields.u32("count")? as usize;
        if data.len() != count.saturating_mul(8) {
            return Err(corrupt(
                path,
                at,
                format!("chunk info lists {count} connections in {} B", data.len()),
            ));
        }
        let counts = data
            .chunks_exact(8)
            .map(|c| {
                let conn = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                (conn, u32::from_le_bytes([c[4], c[5], c[6], c[7]]))
            })
            .collect();
        Ok(ChunkInfo {
            at,
            pos: fields.u64("chunk_pos")?,
            counts,
        })
    }
}

/// The times of an index data record (version 1) \[ns\].
fn index_times(
    fields: &Fields<'_>,
    data: &[u8],
    at: u64,
    path: &Path,
) -> Result<Vec<u64>, SourceError> {
    let ver = fields.u32("ver")?;
    if ver != 1 {
        return Err(corrupt(
            path,
            at,
            format!("index data version {ver} (only 1 is known)"),
        ));
    }
    let count = fields.u32("count")? as usize;
    if data.len() != count.saturating_mul(12) {
        return Err(corrupt(
            path,
            at,
            format!("index data lists {count} messages in {} B", data.len()),
        ));
    }
    Ok(data
        .chunks_exact(12)
        .map(|e| time_ns([e[0], e[1], e[2], e[3], e[4], e[5], e[6], e[7]]))
        .collect())
}

/// What is known of the topics so far: connections, and per topic its messages.
#[derive(Debug, Default)]
struct Catalogue {
    /// Connection id -> index into `topics`.
    conns: HashMap<u32, usize>,
    topics: Vec<TopicInfo>,
}

impl Catalogue {
    /// Learns a connection record (`fields` its header, `data` its connection header).
    fn add_connection(
        &mut self,
        fields: &Fields<'_>,
        data: &[u8],
        path: &Path,
    ) -> Result<(), SourceError> {
        let conn = fields.u32("conn")?;
        let topic = fields.string("topic")?;
        let msg_type = Fields::parse(data, fields.at, path)?.string("type")?;
        let msg_type = normalise_type(msg_type);
        let id = match self.topics.iter().position(|t| t.topic == topic) {
            Some(id) => id,
            None => {
                self.topics.push(TopicInfo {
                    topic: topic.into(),
                    msg_type,
                    count: 0,
                    span_ns: None,
                });
                self.topics.len() - 1
            }
        };
        self.conns.insert(conn, id);
        Ok(())
    }

    /// The topic of connection `conn`, counting one more message at `time_ns`; returns it and the
    /// message's index among its topic's.
    fn count(
        &mut self,
        conn: u32,
        time_ns: u64,
        at: u64,
        path: &Path,
    ) -> Result<(&TopicInfo, u64), SourceError> {
        let id = *self.conns.get(&conn).ok_or_else(|| {
            corrupt(
                path,
                at,
                format!(
                    "message on connection {conn}, which no connection record before it defines"
                ),
            )
        })?;
        let t = &mut self.topics[id];
        let index = t.count;
        t.count += 1;
        t.span_ns = Some(match t.span_ns {
            None => (time_ns, time_ns),
            Some((a, b)) => (a.min(time_ns), b.max(time_ns)),
        });
        Ok((t, index))
    }

    /// Counts the messages of an index data record.
    fn indexed(
        &mut self,
        conn: u32,
        times: &[u64],
        at: u64,
        path: &Path,
    ) -> Result<(), SourceError> {
        for &t in times {
            self.count(conn, t, at, path)?;
        }
        Ok(())
    }

    /// Counts a message data record and hands it to `f`.
    fn message<E: From<SourceError>>(
        &mut self,
        fields: &Fields<'_>,
        data: &[u8],
        at: u64,
        path: &Path,
        f: &mut dyn FnMut(RawMessage<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        let conn = fields.u32("conn")?;
        let log_time_ns = fields.time_ns("time")?;
        let (t, index) = self.count(conn, log_time_ns, at, path)?;
        f(RawMessage {
            topic: &t.topic,
            msg_type: &t.msg_type,
            log_time_ns,
            index,
            data,
            encoding: Encoding::Ros1,
        })
    }

    /// The topics, sorted by name.
    fn topics(self) -> Vec<TopicInfo> {
        let mut topics = self.topics;
        topics.sort_by(|a, b| a.topic.cmp(&b.topic));
        topics
    }
}

/// A decompressed chunk.
struct Chunk {
    /// Offset of the chunk record \[B\].
    at: u64,
    /// Offset of its data in the file when stored uncompressed \[B\].
    plain_at: Option<u64>,
    compression: String,
    data: Vec<u8>,
}

impl Chunk {
    /// A corruption at byte `off` of the decompressed data: the file offset when the chunk is
    /// stored uncompressed, else the chunk's.
    fn corrupt(&self, path: &Path, off: usize, why: &str) -> SourceError {
        match self.plain_at {
            Some(p) => corrupt(path, p + off as u64, why),
            None => corrupt(
                path,
                self.at,
                format!(
                    "{why} (byte {off} of the chunk's {} data, decompressed)",
                    self.compression
                ),
            ),
        }
    }
}

/// Calls `f` on the messages of `chunk` in order, learning its connection records.
fn walk_chunk<E: From<SourceError>>(
    chunk: &Chunk,
    path: &Path,
    cat: &mut Catalogue,
    f: &mut dyn FnMut(RawMessage<'_>) -> Result<(), E>,
) -> Result<(), E> {
    let mut pos = 0;
    while pos < chunk.data.len() {
        let (header, data, next) =
            slice_record(&chunk.data, pos).map_err(|why| chunk.corrupt(path, pos, &why))?;
        let at = chunk.plain_at.map_or(chunk.at, |p| p + pos as u64);
        let fields = Fields::parse(header, at, path)?;
        match fields.op()? {
            OP_MSG_DATA => cat.message(&fields, data, at, path, f)?,
            OP_CONNECTION => cat.add_connection(&fields, data, path)?,
            op => {
                return Err(chunk
                    .corrupt(
                        path,
                        pos,
                        &format!("unexpected record op {op:#04x} inside a chunk"),
                    )
                    .into())
            }
        }
        pos = next;
    }
    Ok(())
}

/// The record at `pos` of `buf`: its header, its data and where the next record starts.
fn slice_record(buf: &[u8], pos: usize) -> Result<(&[u8], &[u8], usize), String> {
    let take = |at: usize, what: &str| -> Result<(&[u8], usize), String> {
        let (len, rest) =
            split_u32(&buf[at..]).ok_or_else(|| format!("the {what} length is cut short"))?;
        let len = len as usize;
        if len > rest.len() {
            return Err(format!(
                "the {what} claims {len} B, {} B left in the chunk",
                rest.len()
            ));
        }
        Ok((&rest[..len], at + 4 + len))
    };
    let (header, at) = take(pos, "record header")?;
    let (data, next) = take(at, "record data")?;
    Ok((header, data, next))
}

/// A record header read from the file; its data not read yet.
struct RecordHead {
    /// Offset of the record \[B\].
    at: u64,
    header: Vec<u8>,
    /// Length of the data \[B\], which starts at the scanner's position.
    data_len: u32,
}

/// A buffered reader of the file that knows its position and the file's length.
struct Scanner<'p> {
    path: &'p Path,
    file: BufReader<File>,
    /// Position \[B\].
    pos: u64,
    /// File length \[B\].
    len: u64,
}

impl<'p> Scanner<'p> {
    fn open(path: &'p Path) -> Result<Scanner<'p>, SourceError> {
        let io = |error| SourceError::Io {
            path: path.into(),
            error,
        };
        let file = File::open(path).map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        Ok(Scanner {
            path,
            file: BufReader::new(file),
            pos: 0,
            len,
        })
    }

    fn io(&self, error: std::io::Error) -> SourceError {
        SourceError::Io {
            path: self.path.into(),
            error,
        }
    }

    fn seek(&mut self, pos: u64) -> Result<(), SourceError> {
        self.file
            .seek(SeekFrom::Start(pos))
            .map_err(|e| self.io(e))?;
        self.pos = pos;
        Ok(())
    }

    /// Reads until `buf` is full or the file ends; returns the bytes read.
    fn read_up_to(&mut self, buf: &mut [u8]) -> Result<usize, SourceError> {
        let mut n = 0;
        while n < buf.len() {
            let k = self.file.read(&mut buf[n..]).map_err(|e| self.io(e))?;
            if k == 0 {
                break;
            }
            n += k;
        }
        self.pos += n as u64;
        Ok(n)
    }

    fn read_exact(&mut self, buf: &mut [u8]) -> Result<(), SourceError> {
        let at = self.pos;
        if self.read_up_to(buf)? < buf.len() {
            return Err(corrupt(
                self.path,
                at,
                format!("truncated: the file ends at {} B", self.len),
            ));
        }
        Ok(())
    }

    fn u32(&mut self) -> Result<u32, SourceError> {
        let mut b = [0u8; 4];
        self.read_exact(&mut b)?;
        Ok(u32::from_le_bytes(b))
    }

    /// A `u32` length of something that must fit in what is left of the file.
    fn length(&mut self, what: &str) -> Result<u32, SourceError> {
        let at = self.pos;
        let len = self.u32()?;
        let left = self.len.saturating_sub(self.pos);
        if u64::from(len) > left {
            return Err(corrupt(
                self.path,
                at,
                format!("{what} claims {len} B, {left} B left in the file"),
            ));
        }
        Ok(len)
    }

    /// The next record's header, if it starts before `end`; its data must end by `end`.
    fn next_record(&mut self, end: u64) -> Result<Option<RecordHead>, SourceError> {
        let at = self.pos;
        if at == end {
            return Ok(None);
        }
        if at >= self.len {
            return Err(corrupt(
                self.path,
                at,
                format!("truncated: the file ends at {} B, before {end} B", self.len),
            ));
        }
        let header_len = self.length("the record header")?;
        let mut header = vec![0u8; header_len as usize];
        self.read_exact(&mut header)?;
        let data_len = self.length("the record data")?;
        if self.pos + u64::from(data_len) > end {
            return Err(corrupt(
                self.path,
                at,
                format!("the record ({data_len} B of data) runs past {end} B"),
            ));
        }
        Ok(Some(RecordHead {
            at,
            header,
            data_len,
        }))
    }

    fn read_data(&mut self, rec: &RecordHead) -> Result<Vec<u8>, SourceError> {
        let mut data = vec![0u8; rec.data_len as usize];
        self.read_exact(&mut data)?;
        Ok(data)
    }

    fn skip_data(&mut self, rec: &RecordHead) -> Result<(), SourceError> {
        self.file
            .seek_relative(i64::from(rec.data_len))
            .map_err(|e| self.io(e))?;
        self.pos += u64::from(rec.data_len);
        Ok(())
    }

    /// The data of chunk record `rec`, decompressed.
    fn read_chunk(&mut self, rec: &RecordHead, fields: &Fields<'_>) -> Result<Chunk, SourceError> {
        let compression = fields.string("compression")?;
        let size = fields.u32("size")?;
        let plain_at = (compression == "none").then_some(self.pos);
        let data = match compression {
            "none" if size == rec.data_len => self.read_data(rec)?,
            "none" => {
                let why = format!("uncompressed chunk of {} B says size {size}", rec.data_len);
                return Err(corrupt(self.path, rec.at, why));
            }
            "bz2" | "lz4" => self.inflate(rec, compression, size)?,
            other => {
                return Err(SourceError::Unsupported {
                    path: self.path.into(),
                    what: format!("chunk compression `{other}` (chunk at {} B)", rec.at),
                })
            }
        };
        Ok(Chunk {
            at: rec.at,
            plain_at,
            compression: compression.into(),
            data,
        })
    }

    /// Decompresses the data of `rec` (`bz2` or `lz4`), expecting `size` bytes, and leaves the
    /// scanner after the record. Streams from the file: only the output is held.
    fn inflate(
        &mut self,
        rec: &RecordHead,
        compression: &str,
        size: u32,
    ) -> Result<Vec<u8>, SourceError> {
        let mut src = (&mut self.file).take(u64::from(rec.data_len));
        let mut out = Vec::with_capacity((size as usize).min(RESERVE_MAX));
        let limit = u64::from(size) + 1;
        let res = if compression == "bz2" {
            bzip2::read::BzDecoder::new(&mut src)
                .take(limit)
                .read_to_end(&mut out)
        } else {
            lz4_flex::frame::FrameDecoder::new(&mut src)
                .take(limit)
                .read_to_end(&mut out)
        };
        let left = src.limit();
        self.file
            .seek_relative(left as i64)
            .map_err(|e| self.io(e))?;
        self.pos += u64::from(rec.data_len);
        let bad =
            |why: String| corrupt(self.path, rec.at, format!("the {compression} chunk {why}"));
        res.map_err(|e| bad(format!("does not decompress: {e}")))?;
        if out.len() != size as usize {
            let got = if out.len() > size as usize {
                "more".to_string()
            } else {
                format!("{} B", out.len())
            };
            return Err(bad(format!(
                "decompresses to {got}, its header says {size} B"
            )));
        }
        Ok(out)
    }
}
