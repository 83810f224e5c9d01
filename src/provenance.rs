//! What makes a recording traceable: when it started on the wall clock (UTC, ISO 8601), which
//! forcecell wrote it, from which cell file (its SHA-256), which sensor (its identity), and why it
//! ended — written as MCAP metadata and as a JSON summary beside the recording — and the ISO-dated
//! file names.

use std::fmt::Write as _;
use std::time::{SystemTime, UNIX_EPOCH};

use serde::Serialize;
use sha2::{Digest, Sha256};

/// A UTC instant as `YYYY-MM-DDTHH:MM:SS.mmmZ` (ISO 8601 / RFC 3339).
pub fn iso8601(t: SystemTime) -> String {
    let (date, hms, ms) = civil(t);
    format!("{date}T{hms}.{ms:03}Z")
}

/// A UTC instant for a file name: `YYYY-MM-DDTHH-MM-SSZ` (no `:`, which some file systems refuse).
pub fn file_stamp(t: SystemTime) -> String {
    let (date, hms, _) = civil(t);
    format!("{date}T{}Z", hms.replace(':', "-"))
}

/// `(YYYY-MM-DD, HH:MM:SS, milliseconds)` of `t` in UTC (times before 1970 read as 1970).
fn civil(t: SystemTime) -> (String, String, u32) {
    let d = t.duration_since(UNIX_EPOCH).unwrap_or_default();
    let secs = d.as_secs();
    let (days, rem) = (secs / 86_400, secs % 86_400);
    // Days since 1970-01-01 to a proleptic Gregorian date (Howard Hinnant's `civil_from_days`).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1_460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    (
        format!("{year:04}-{month:02}-{day:02}"),
        format!("{:02}:{:02}:{:02}", rem / 3600, rem % 3600 / 60, rem % 60),
        d.subsec_millis(),
    )
}

/// The SHA-256 of `bytes`, lower-case hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    let digest = Sha256::digest(bytes);
    let mut s = String::with_capacity(64);
    for b in digest {
        let _ = write!(s, "{b:02x}");
    }
    s
}

/// What a recording came from and how it ended: the MCAP metadata record `forcecell.run` and the JSON
/// summary beside the recording carry the same fields.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Provenance {
    /// The command (`run`, `sim`, `calibrate`, `bench-scenarios`).
    pub command: String,
    /// forcecell's version.
    pub forcecell: String,
    /// Wall-clock start, UTC, ISO 8601.
    pub started: String,
    /// Wall-clock end, UTC, ISO 8601 (empty while running).
    pub ended: String,
    /// The cell file or scenario it ran, as given.
    pub source: String,
    /// The SHA-256 of that file's bytes (empty for a built-in scenario).
    pub source_sha256: String,
    /// The tuning's name.
    pub tuning: String,
    /// The sensor as configured (model, port or bus, address).
    pub sensor: String,
    /// The sensor's serial number as it reported it, or `unknown`.
    pub sensor_serial: String,
    /// The sensor's firmware version as it reported it, or `unknown`.
    pub sensor_firmware: String,
    /// The robot link (its kind and address).
    pub robot: String,
    /// Why it ended, in words.
    pub end_reason: String,
    /// Whether the robot got its `Stop`.
    pub stop_sent: bool,
    /// Cycles answered.
    pub cycles: u64,
}

impl Provenance {
    /// A record for `command` started now from `source`, whose `bytes` (a file's, as the command
    /// read it; `None` for a built-in name) are hashed.
    pub fn start(command: &str, source: &str, bytes: Option<&[u8]>) -> Self {
        let source_sha256 = bytes.map(sha256_hex).unwrap_or_default();
        Self {
            command: command.into(),
            forcecell: env!("CARGO_PKG_VERSION").into(),
            started: iso8601(SystemTime::now()),
            source: source.into(),
            source_sha256,
            sensor_serial: crate::cell::UNKNOWN.into(),
            sensor_firmware: crate::cell::UNKNOWN.into(),
            ..Self::default()
        }
    }

    /// Record what the sensor said of itself.
    pub fn identify_sensor(&mut self, id: &crate::cell::SensorIdentity) {
        self.sensor_serial = id.serial.clone();
        self.sensor_firmware = id.firmware.clone();
    }

    /// Mark the end now, with its reason.
    pub fn finish(&mut self, reason: &str, stop_sent: bool, cycles: u64) {
        self.ended = iso8601(SystemTime::now());
        self.end_reason = reason.into();
        self.stop_sent = stop_sent;
        self.cycles = cycles;
    }

    /// The fields as MCAP metadata (string to string).
    pub fn metadata(&self) -> std::collections::BTreeMap<String, String> {
        let v = serde_json::to_value(self).expect("plain fields serialise");
        v.as_object()
            .expect("a struct is an object")
            .iter()
            .map(|(k, v)| {
                let s = match v {
                    serde_json::Value::String(s) => s.clone(),
                    other => other.to_string(),
                };
                (k.clone(), s)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn instants_read_as_utc_dates() {
        let at = |s: u64, ms: u64| UNIX_EPOCH + Duration::from_millis(s * 1000 + ms);
        assert_eq!(iso8601(at(0, 0)), "1970-01-01T00:00:00.000Z");
        // 2000-02-29 (a leap day of a century leap year) 12:34:56.789
        assert_eq!(iso8601(at(951_827_696, 789)), "2000-02-29T12:34:56.789Z");
        // 2026-12-04 19:58:49
        assert_eq!(iso8601(at(1_796_414_329, 5)), "2026-12-04T19:58:49.005Z");
        assert_eq!(file_stamp(at(1_796_414_329, 5)), "2026-12-04T19-58-49Z");
        // The last second of 2100 (not a leap year) and the first of 2101.
        assert_eq!(iso8601(at(4_133_980_799, 0)), "2100-12-31T23:59:59.000Z");
        assert_eq!(iso8601(at(4_133_980_800, 0)), "2101-01-01T00:00:00.000Z");
    }

    #[test]
    fn the_hash_is_sha256() {
        // FIPS 180-2's test vector.
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn a_record_hashes_its_file_and_says_how_it_ended() {
        let dir = tempfile::tempdir().unwrap();
        let cell = dir.path().join("cell.toml");
        std::fs::write(&cell, "abc").unwrap();
        let bytes = std::fs::read(&cell).unwrap();
        let mut p = Provenance::start("run", cell.to_str().unwrap(), Some(&bytes));
        assert_eq!(
            p.source_sha256,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert!(p.started.ends_with('Z') && p.ended.is_empty());
        p.finish("the robot ended RSI", true, 3001);
        let m = p.metadata();
        assert_eq!(m["end_reason"], "the robot ended RSI");
        assert_eq!(m["stop_sent"], "true");
        assert_eq!(m["cycles"], "3001");
        assert_eq!(m["forcecell"], env!("CARGO_PKG_VERSION"));
        assert_eq!(
            (m["sensor_serial"].as_str(), m["sensor_firmware"].as_str()),
            ("unknown", "unknown")
        );
        p.identify_sensor(&crate::cell::SensorIdentity {
            serial: "FTS-875704368".into(),
            firmware: "FTS-3.1.0".into(),
        });
        assert_eq!(p.metadata()["sensor_serial"], "FTS-875704368");
        let built_in = Provenance::start("sim", "paper-fig9", None);
        assert_eq!(built_in.source_sha256, "", "a built-in name is no file");
    }
}
