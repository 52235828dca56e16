//! ROS 2 bag directories: `metadata.yaml` with sqlite3 `.db3` or MCAP storage.
//!
//! `metadata.yaml` (`rosbag2_bagfile_information`) names the storage (`storage_identifier`:
//! `sqlite3` or `mcap`), the files in order (`relative_file_paths`), the topics
//! (`topics_with_message_count`) and the compression (`compression_format` /
//! `compression_mode`). It is parsed with `yaml-rust2`: the file is plain block YAML, but writers
//! differ in quoting, flow lists (`[]`), folded scalars and multi-line QoS strings, and a real
//! YAML 1.2 parser takes all of them where a hand-written subset parser would guess.
//!
//! sqlite3 storage: each `.db3` is opened read-only and its `messages` rows are streamed one at
//! a time in `timestamp` order (memory: one row). MCAP storage: each file is read with
//! [`McapFile`]. Compression (zstd only, as rosbag2 writes it): `message` mode decompresses each
//! payload; `file` mode decompresses each file, streaming, to a temporary file that is deleted
//! when it has been read.
//!
//! Errors name `metadata.yaml` (with the key) or the storage file (with the sqlite row id, or
//! the MCAP byte offset).

use super::mcap::{merge_span, McapFile, Span};
use super::{RawMessage, Source, SourceError, TopicInfo};
use crate::ros::{normalise_type, Encoding};
use crate::ImportError;
use rusqlite::{Connection, OpenFlags};
use std::collections::HashMap;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use yaml_rust2::{Yaml, YamlLoader};

/// Where a bag keeps its messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Storage {
    /// sqlite3 `.db3` files.
    Sqlite3,
    /// MCAP files.
    Mcap,
}

/// How a bag is compressed (the format is always zstd).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compression {
    /// Not compressed.
    None,
    /// Each storage file is one zstd stream (`x.db3.zstd`).
    File,
    /// Each message payload is one zstd frame.
    Message,
}

/// A topic as `metadata.yaml` lists it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MetaTopic {
    /// Topic.
    pub name: String,
    /// Message type as written (`pkg/msg/Type`).
    pub msg_type: String,
    /// `cdr` (or `ros1`).
    pub serialization_format: String,
    /// Messages, as the recorder counted them.
    pub message_count: u64,
}

/// What `metadata.yaml` says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Metadata {
    /// `version` of the metadata layout.
    pub version: i64,
    /// `storage_identifier`.
    pub storage: Storage,
    /// `relative_file_paths`, resolved against the bag directory, in order.
    pub files: Vec<PathBuf>,
    /// `topics_with_message_count`.
    pub topics: Vec<MetaTopic>,
    /// `compression_mode` (with `compression_format` zstd).
    pub compression: Compression,
}

/// The serialisation a `serialization_format` names (`None`: one this crate does not decode).
fn encoding_of(format: &str) -> Option<Encoding> {
    match format {
        "cdr" => Some(Encoding::Cdr),
        "ros1" => Some(Encoding::Ros1),
        _ => None,
    }
}

fn bad_yaml(path: &Path, at: u64, why: impl Into<String>) -> SourceError {
    SourceError::Corrupt {
        path: path.into(),
        at,
        why: why.into(),
    }
}

/// `node[k]`, or an error naming the key path.
fn key<'a>(path: &Path, node: &'a Yaml, at: &str, k: &str) -> Result<&'a Yaml, SourceError> {
    let v = &node[k];
    if v.is_badvalue() {
        return Err(bad_yaml(path, 0, format!("missing key `{at}.{k}`")));
    }
    Ok(v)
}

fn str_key<'a>(path: &Path, node: &'a Yaml, at: &str, k: &str) -> Result<&'a str, SourceError> {
    key(path, node, at, k)?
        .as_str()
        .ok_or_else(|| bad_yaml(path, 0, format!("`{at}.{k}` is not a string")))
}

fn int_key(path: &Path, node: &Yaml, at: &str, k: &str) -> Result<i64, SourceError> {
    key(path, node, at, k)?
        .as_i64()
        .ok_or_else(|| bad_yaml(path, 0, format!("`{at}.{k}` is not an integer")))
}

/// A list key; YAML `null` (`key:` with nothing after it) is the empty list.
fn list_key<'a>(path: &Path, node: &'a Yaml, at: &str, k: &str) -> Result<&'a [Yaml], SourceError> {
    let v = key(path, node, at, k)?;
    if v.is_null() {
        return Ok(&[]);
    }
    v.as_vec()
        .map(Vec::as_slice)
        .ok_or_else(|| bad_yaml(path, 0, format!("`{at}.{k}` is not a list")))
}

/// An optional string key (absent or null: empty).
fn opt_str<'a>(node: &'a Yaml, k: &str) -> &'a str {
    node[k].as_str().unwrap_or("")
}

impl Metadata {
    /// Parses the text of `yaml_path` (a bag's `metadata.yaml`); file names are resolved against
    /// `dir`. Errors name `yaml_path` and the key (or, for YAML syntax errors, the character
    /// offset).
    pub fn parse(text: &str, yaml_path: &Path, dir: &Path) -> Result<Metadata, SourceError> {
        let p = yaml_path;
        let docs = YamlLoader::load_from_str(text).map_err(|e| {
            bad_yaml(
                p,
                e.marker().index() as u64,
                format!(
                    "YAML syntax error at line {} column {}: {}",
                    e.marker().line(),
                    e.marker().col() + 1,
                    e.info()
                ),
            )
        })?;
        let doc = docs
            .first()
            .ok_or_else(|| bad_yaml(p, 0, "empty document"))?;
        let top = "rosbag2_bagfile_information";
        let info = &doc[top];
        if info.is_badvalue() {
            return Err(bad_yaml(p, 0, format!("missing key `{top}`")));
        }
        let version = int_key(p, info, top, "version")?;
        let storage = match str_key(p, info, top, "storage_identifier")? {
            "sqlite3" => Storage::Sqlite3,
            "mcap" => Storage::Mcap,
            other => {
                return Err(SourceError::Unsupported {
                    path: p.into(),
                    what: format!(
                        "`{top}.storage_identifier` is `{other}` (this reader reads sqlite3 and \
                         mcap)"
                    ),
                })
            }
        };
        let mut files = Vec::new();
        for (i, f) in list_key(p, info, top, "relative_file_paths")?
            .iter()
            .enumerate()
        {
            let name = f.as_str().ok_or_else(|| {
                bad_yaml(
                    p,
                    0,
                    format!("`{top}.relative_file_paths[{i}]` is not a string"),
                )
            })?;
            files.push(resolve(dir, name));
        }
        let mut topics = Vec::new();
        for (i, t) in list_key(p, info, top, "topics_with_message_count")?
            .iter()
            .enumerate()
        {
            let at = format!("{top}.topics_with_message_count[{i}]");
            let count = int_key(p, t, &at, "message_count")?;
            let m = key(p, t, &at, "topic_metadata")?;
            let at = format!("{at}.topic_metadata");
            topics.push(MetaTopic {
                name: str_key(p, m, &at, "name")?.to_string(),
                msg_type: str_key(p, m, &at, "type")?.to_string(),
                serialization_format: str_key(p, m, &at, "serialization_format")?.to_string(),
                message_count: u64::try_from(count)
                    .map_err(|_| bad_yaml(p, 0, format!("`{at}.message_count` is negative")))?,
            });
        }
        // Both keys are absent before metadata version 3 and empty when not compressed.
        let format = opt_str(info, "compression_format");
        let mode = opt_str(info, "compression_mode").to_ascii_lowercase();
        let compression = match mode.as_str() {
            // `storage`: the storage plugin compresses (MCAP chunks), nothing for the bag to do.
            "" | "none" | "storage" => Compression::None,
            "file" | "message" if format.eq_ignore_ascii_case("zstd") => {
                if mode == "file" {
                    Compression::File
                } else {
                    Compression::Message
                }
            }
            _ => {
                return Err(SourceError::Unsupported {
                    path: p.into(),
                    what: format!(
                        "compression `{format}` in `{mode}` mode (this reader reads zstd in file \
                         or message mode)"
                    ),
                })
            }
        };
        Ok(Metadata {
            version,
            storage,
            files,
            topics,
            compression,
        })
    }
}

/// `dir/name`; older rosbag2 wrote the bag directory into the name (`bag/bag_0.db3`), so when
/// that does not exist but `dir/<file name>` does, the latter.
fn resolve(dir: &Path, name: &str) -> PathBuf {
    let p = dir.join(name);
    if !p.exists() {
        if let Some(f) = Path::new(name).file_name() {
            let q = dir.join(f);
            if q.exists() {
                return q;
            }
        }
    }
    p
}

/// A reader that counts the bytes it passed on (for error offsets).
struct Counting<R> {
    inner: R,
    n: u64,
}

impl<R: Read> Read for Counting<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let k = self.inner.read(buf)?;
        self.n += k as u64;
        Ok(k)
    }
}

/// Decompresses the zstd file `src`, streaming, into a temporary file (deleted when the returned
/// path is dropped). Errors name `src` and the compressed byte offset reached.
fn unzstd_to_temp(src: &Path) -> Result<tempfile::TempPath, SourceError> {
    let io = |error| SourceError::Io {
        path: src.into(),
        error,
    };
    let f = File::open(src).map_err(io)?;
    let mut input = Counting {
        inner: std::io::BufReader::new(f),
        n: 0,
    };
    let mut tmp = tempfile::Builder::new()
        .prefix("milliego-ros2-")
        .tempfile()
        .map_err(|error| SourceError::Io {
            path: std::env::temp_dir(),
            error,
        })?;
    let r = zstd::stream::read::Decoder::new(&mut input)
        .and_then(|mut dec| std::io::copy(&mut dec, tmp.as_file_mut()));
    if let Err(e) = r {
        return Err(SourceError::Corrupt {
            path: src.into(),
            at: input.n,
            why: format!("zstd file decompression failed: {e}"),
        });
    }
    Ok(tmp.into_temp_path())
}

/// Decompresses one message payload (message-mode compression).
fn unzstd_message(data: &[u8]) -> Result<Vec<u8>, String> {
    zstd::stream::decode_all(data).map_err(|e| format!("zstd message decompression failed: {e}"))
}

/// Checks that the sqlite file `file` (shown as `path` in errors) is whole: sqlite reads the
/// missing tail of a truncated file as zeros and reports no error, so a cut recording would
/// silently yield zeroed payloads. The file must hold whole pages, and (when the header's page
/// count is valid and no `-wal` file may hold newer pages) as many as the header says.
fn check_sqlite_length(file: &Path, path: &Path) -> Result<(), SourceError> {
    let io = |error| SourceError::Io {
        path: path.into(),
        error,
    };
    let mut f = File::open(file).map_err(io)?;
    let len = f.metadata().map_err(io)?.len();
    let corrupt = |why: String| SourceError::Corrupt {
        path: path.into(),
        at: len,
        why,
    };
    let mut h = [0u8; 100];
    if len < h.len() as u64 {
        return Err(corrupt(format!(
            "{len} B, shorter than the 100-byte sqlite header (truncated?)"
        )));
    }
    f.read_exact(&mut h).map_err(io)?;
    if &h[..16] != b"SQLite format 3\0" {
        return Err(SourceError::Corrupt {
            path: path.into(),
            at: 0,
            why: "not an sqlite3 database (no `SQLite format 3` header)".into(),
        });
    }
    let page = match u16::from_be_bytes([h[16], h[17]]) {
        1 => 65536,
        p => u64::from(p),
    };
    if page < 512 || !page.is_power_of_two() {
        return Err(SourceError::Corrupt {
            path: path.into(),
            at: 16,
            why: format!("sqlite header: page size {page} B"),
        });
    }
    if len % page != 0 {
        return Err(corrupt(format!(
            "{len} B is not a whole number of {page} B pages (truncated?)"
        )));
    }
    let pages = u64::from(u32::from_be_bytes([h[28], h[29], h[30], h[31]]));
    let count_valid = h[92..96] == h[24..28] && pages > 0;
    let mut wal = file.as_os_str().to_owned();
    wal.push("-wal");
    if count_valid && !Path::new(&wal).exists() && len < pages * page {
        return Err(corrupt(format!(
            "{len} B, the header says {pages} pages of {page} B (truncated?)"
        )));
    }
    Ok(())
}

/// A `.db3` opened read-only (decompressed first in file mode).
struct Db {
    /// The file as the bag names it (for errors).
    path: PathBuf,
    conn: Connection,
    /// Topic id -> (topic, type normalised, encoding).
    topics: HashMap<i64, (String, String, Option<Encoding>)>,
    /// Topic ids in table order.
    order: Vec<i64>,
    _tmp: Option<tempfile::TempPath>,
}

impl Db {
    fn corrupt(&self, row: i64, why: impl Into<String>) -> SourceError {
        SourceError::Corrupt {
            path: self.path.clone(),
            at: u64::try_from(row).unwrap_or(0),
            why: why.into(),
        }
    }

    fn sql(&self, row: i64, e: &rusqlite::Error) -> SourceError {
        self.corrupt(row, format!("sqlite: {e}"))
    }

    fn open(path: &Path, compression: Compression) -> Result<Db, SourceError> {
        if let Err(error) = std::fs::metadata(path) {
            return Err(SourceError::Io {
                path: path.into(),
                error,
            });
        }
        let tmp = match compression {
            Compression::File => Some(unzstd_to_temp(path)?),
            _ => None,
        };
        let file: &Path = tmp.as_deref().unwrap_or(path);
        check_sqlite_length(file, path)?;
        let sql = |e: rusqlite::Error| SourceError::Corrupt {
            path: path.into(),
            at: 0,
            why: format!("sqlite: {e}"),
        };
        let conn = Connection::open_with_flags(
            file,
            OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
        )
        .map_err(sql)?;
        let mut db = Db {
            path: path.into(),
            conn,
            topics: HashMap::new(),
            order: Vec::new(),
            _tmp: tmp,
        };
        let mut stmt = db
            .conn
            .prepare("SELECT id, name, type, serialization_format FROM topics ORDER BY id")
            .map_err(sql)?;
        let mut rows = stmt.query([]).map_err(sql)?;
        let mut topics = Vec::new();
        while let Some(row) = rows.next().map_err(sql)? {
            let get = |row: &rusqlite::Row<'_>| -> rusqlite::Result<(i64, String, String, String)> {
                Ok((row.get(0)?, row.get(1)?, row.get(2)?, row.get(3)?))
            };
            let (id, name, ty, format) = get(row).map_err(|e| SourceError::Corrupt {
                path: path.into(),
                at: 0,
                why: format!("topics table: sqlite: {e}"),
            })?;
            topics.push((id, (name, normalise_type(&ty), encoding_of(&format))));
        }
        drop(rows);
        drop(stmt);
        for (id, t) in topics {
            db.order.push(id);
            db.topics.insert(id, t);
        }
        Ok(db)
    }

    /// Per topic id: (messages, log-time span \[ns\]).
    fn counts(&self) -> Result<HashMap<i64, (u64, Span)>, SourceError> {
        let mut stmt = self
            .conn
            .prepare(
                "SELECT topic_id, COUNT(*), MIN(timestamp), MAX(timestamp) FROM messages \
                 GROUP BY topic_id",
            )
            .map_err(|e| self.sql(0, &e))?;
        let mut rows = stmt.query([]).map_err(|e| self.sql(0, &e))?;
        let mut out = HashMap::new();
        while let Some(row) = rows.next().map_err(|e| self.sql(0, &e))? {
            let get = |row: &rusqlite::Row<'_>| -> rusqlite::Result<(i64, i64, i64, i64)> {
                Ok((row.get(0)?, row.get(1)?, row.get(2)?, row.get(3)?))
            };
            let (id, n, t0, t1) = get(row).map_err(|e| self.sql(0, &e))?;
            let (Ok(n), Ok(t0), Ok(t1)) = (u64::try_from(n), u64::try_from(t0), u64::try_from(t1))
            else {
                return Err(self.corrupt(0, format!("topic id {id}: a negative timestamp")));
            };
            out.insert(id, (n, Some((t0, t1))));
        }
        Ok(out)
    }
}

/// A ROS 2 bag directory opened for reading.
#[derive(Debug)]
pub struct Ros2Bag {
    path: PathBuf,
    meta: Metadata,
}

impl Ros2Bag {
    /// Opens `path` and reads its metadata.yaml.
    pub fn open(path: &Path) -> Result<Ros2Bag, SourceError> {
        let yaml = path.join("metadata.yaml");
        let text = match std::fs::read_to_string(&yaml) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(SourceError::UnknownFormat {
                    path: path.into(),
                    why: "a directory without metadata.yaml (not a ROS 2 bag)".into(),
                })
            }
            Err(error) => return Err(SourceError::Io { path: yaml, error }),
        };
        let meta = Metadata::parse(&text, &yaml, path)?;
        Ok(Ros2Bag {
            path: path.into(),
            meta,
        })
    }

    /// What `metadata.yaml` says.
    pub fn metadata(&self) -> &Metadata {
        &self.meta
    }

    /// Opens the MCAP storage file `file` (decompressed first, to a temporary file, in file
    /// mode; errors still name `file`).
    fn open_mcap(
        &self,
        file: &Path,
    ) -> Result<(McapFile, Option<tempfile::TempPath>), SourceError> {
        match self.meta.compression {
            Compression::File => {
                let tmp = unzstd_to_temp(file)?;
                Ok((McapFile::open_copy(&tmp, file)?, Some(tmp)))
            }
            _ => Ok((McapFile::open(file)?, None)),
        }
    }
}

fn add_topic(out: &mut Vec<TopicInfo>, topic: &str, ty: &str, n: u64, span: Option<(u64, u64)>) {
    if let Some(t) = out
        .iter_mut()
        .find(|t| t.topic == topic && t.msg_type == ty)
    {
        t.count += n;
        t.span_ns = merge_span(t.span_ns, span);
    } else {
        out.push(TopicInfo {
            topic: topic.into(),
            msg_type: ty.into(),
            count: n,
            span_ns: span,
        });
    }
}

impl Source for Ros2Bag {
    fn path(&self) -> &Path {
        &self.path
    }

    /// From the storage files (sqlite: the `topics` table and a count over `messages`; MCAP: each
    /// file's summary), merged over the files; topics whose serialisation is not `cdr` or `ros1`
    /// are left out.
    fn topics(&mut self) -> Result<Vec<TopicInfo>, SourceError> {
        let mut out = Vec::new();
        for file in &self.meta.files {
            match self.meta.storage {
                Storage::Sqlite3 => {
                    let db = Db::open(file, self.meta.compression)?;
                    let counts = db.counts()?;
                    for id in &db.order {
                        let (name, ty, enc) = &db.topics[id];
                        if enc.is_none() {
                            continue;
                        }
                        let (n, span) = counts.get(id).copied().unwrap_or((0, None));
                        add_topic(&mut out, name, ty, n, span);
                    }
                }
                Storage::Mcap => {
                    let (mut m, _tmp) = self.open_mcap(file)?;
                    for t in m.topics()? {
                        add_topic(&mut out, &t.topic, &t.msg_type, t.count, t.span_ns);
                    }
                }
            }
        }
        Ok(out)
    }

    /// Files in `relative_file_paths` order; within a file, sqlite rows in `(timestamp, id)`
    /// order, MCAP messages in file order.
    fn for_each(
        &mut self,
        topics: &[&str],
        f: &mut dyn FnMut(RawMessage<'_>) -> Result<(), ImportError>,
    ) -> Result<(), ImportError> {
        let compressed = self.meta.compression == Compression::Message;
        // Per-topic index across all files.
        let mut index: HashMap<String, u64> = HashMap::new();
        let mut next_index = |topic: &str| match index.get_mut(topic) {
            Some(i) => {
                *i += 1;
                *i
            }
            None => {
                index.insert(topic.to_string(), 0);
                0
            }
        };
        for file in &self.meta.files {
            match self.meta.storage {
                Storage::Sqlite3 => {
                    let db = Db::open(file, self.meta.compression)?;
                    let mut ids = Vec::new();
                    for id in &db.order {
                        let (name, _, enc) = &db.topics[id];
                        if !topics.is_empty() && !topics.contains(&name.as_str()) {
                            continue;
                        }
                        if enc.is_none() {
                            if topics.is_empty() {
                                continue;
                            }
                            return Err(SourceError::Unsupported {
                                path: file.clone(),
                                what: format!(
                                    "topic `{name}`: serialization format is not cdr or ros1"
                                ),
                            }
                            .into());
                        }
                        ids.push(id.to_string());
                    }
                    if ids.is_empty() {
                        continue;
                    }
                    let sql = format!(
                        "SELECT id, topic_id, timestamp, data FROM messages \
                         WHERE topic_id IN ({}) ORDER BY timestamp, id",
                        ids.join(",")
                    );
                    let mut stmt = db.conn.prepare(&sql).map_err(|e| db.sql(0, &e))?;
                    let mut rows = stmt.query([]).map_err(|e| db.sql(0, &e))?;
                    let mut last = 0i64;
                    while let Some(row) = rows.next().map_err(|e| db.sql(last, &e))? {
                        let id: i64 = row.get(0).map_err(|e| db.sql(last, &e))?;
                        last = id;
                        let topic_id: i64 = row.get(1).map_err(|e| db.sql(id, &e))?;
                        let t: i64 = row.get(2).map_err(|e| db.sql(id, &e))?;
                        let data = row
                            .get_ref(3)
                            .and_then(|v| v.as_blob().map_err(Into::into))
                            .map_err(|e| db.sql(id, &e))?;
                        let log_time_ns = u64::try_from(t)
                            .map_err(|_| db.corrupt(id, format!("negative timestamp {t}")))?;
                        let (name, ty, enc) = db.topics.get(&topic_id).ok_or_else(|| {
                            db.corrupt(
                                id,
                                format!("topic id {topic_id} is not in the topics table"),
                            )
                        })?;
                        let Some(encoding) = *enc else { continue };
                        let plain;
                        let data = if compressed {
                            plain = unzstd_message(data).map_err(|why| db.corrupt(id, why))?;
                            &plain[..]
                        } else {
                            data
                        };
                        f(RawMessage {
                            topic: name,
                            msg_type: ty,
                            log_time_ns,
                            index: next_index(name),
                            data,
                            encoding,
                        })?;
                    }
                }
                Storage::Mcap => {
                    let (mut m, _tmp) = self.open_mcap(file)?;
                    m.for_each(topics, &mut |msg| {
                        let plain;
                        let data = if compressed {
                            plain =
                                unzstd_message(msg.data).map_err(|why| SourceError::Corrupt {
                                    path: file.clone(),
                                    at: 0,
                                    why: format!(
                                        "topic `{}` message {}: {why}",
                                        msg.topic, msg.index
                                    ),
                                })?;
                            &plain[..]
                        } else {
                            msg.data
                        };
                        f(RawMessage {
                            index: next_index(msg.topic),
                            data,
                            ..msg
                        })
                    })?;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// As rosbag2 (Humble, yaml-cpp) writes it: quoted and multi-line QoS strings, `files`.
    const HUMBLE: &str = r#"rosbag2_bagfile_information:
  version: 5
  storage_identifier: sqlite3
  duration:
    nanoseconds: 1000
  starting_time:
    nanoseconds_since_epoch: 1700000000000000000
  message_count: 3
  topics_with_message_count:
    - topic_metadata:
        name: /radar/points
        type: sensor_msgs/msg/PointCloud2
        serialization_format: cdr
        offered_qos_profiles: "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  deadline:\n    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n  avoid_ros_namespace_conventions: false"
      message_count: 3
    - topic_metadata:
        name: "/imu"
        type: 'sensor_msgs/msg/Imu'
        serialization_format: cdr
        offered_qos_profiles: ""
      message_count: 0
  compression_format: ""
  compression_mode: ""
  relative_file_paths:
    - bag/bag_0.db3
  files:
    - path: bag_0.db3
      starting_time:
        nanoseconds_since_epoch: 1700000000000000000
      duration:
        nanoseconds: 1000
      message_count: 3
"#;

    #[test]
    fn rosbag2_metadata() {
        let m = Metadata::parse(HUMBLE, Path::new("m.yaml"), Path::new("/nonexistent")).unwrap();
        assert_eq!(m.version, 5);
        assert_eq!(m.storage, Storage::Sqlite3);
        assert_eq!(m.compression, Compression::None);
        assert_eq!(m.files, [PathBuf::from("/nonexistent/bag/bag_0.db3")]);
        assert_eq!(m.topics.len(), 2);
        assert_eq!(m.topics[0].name, "/radar/points");
        assert_eq!(m.topics[0].message_count, 3);
        assert_eq!(m.topics[1].name, "/imu");
        assert_eq!(m.topics[1].msg_type, "sensor_msgs/msg/Imu");
        assert_eq!(m.topics[1].serialization_format, "cdr");

        // Older layouts: no compression keys, an empty topic list in flow style; upper-case
        // mode names.
        let old = "rosbag2_bagfile_information:\n  version: 2\n  storage_identifier: mcap\n  \
                   relative_file_paths: [x.mcap]\n  topics_with_message_count: []\n";
        let m = Metadata::parse(old, Path::new("m.yaml"), Path::new("d")).unwrap();
        assert_eq!(
            (m.storage, m.compression),
            (Storage::Mcap, Compression::None)
        );
        assert!(m.topics.is_empty());
        let msg = HUMBLE
            .replace("compression_format: \"\"", "compression_format: zstd")
            .replace("compression_mode: \"\"", "compression_mode: MESSAGE");
        let m = Metadata::parse(&msg, Path::new("m.yaml"), Path::new("d")).unwrap();
        assert_eq!(m.compression, Compression::Message);
    }

    #[test]
    fn metadata_errors_name_the_key() {
        let p = Path::new("bag/metadata.yaml");
        let e = Metadata::parse(
            &HUMBLE.replace("        type: 'sensor_msgs/msg/Imu'\n", ""),
            p,
            p,
        )
        .unwrap_err();
        let s = e.to_string();
        assert!(s.starts_with("bag/metadata.yaml"), "{s}");
        assert!(
            s.contains(
                "rosbag2_bagfile_information.topics_with_message_count[1].topic_metadata.type"
            ),
            "{s}"
        );
        let e = Metadata::parse("other: 1\n", p, p).unwrap_err();
        assert!(e.to_string().contains("rosbag2_bagfile_information"), "{e}");
        let e = Metadata::parse(&HUMBLE.replace("version: 5", "version: five"), p, p).unwrap_err();
        assert!(e.to_string().contains("not an integer"), "{e}");
        assert!(Metadata::parse("", p, p).is_err());
        assert!(Metadata::parse("- [", p, p).is_err());
    }
}
