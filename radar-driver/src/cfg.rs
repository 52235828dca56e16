//! TI mmWave `.cfg` files: line parsing, the chirp configuration, and the quantities it implies.
//!
//! Parsing is line by line and keeps going over commands it does not model (tracking, static
//! detection, monitoring ...): they are [`Command::Other`] and are still uploaded. Derived
//! quantities follow the SDK's rfparser, including the CLI's quantisation of frequencies, slopes
//! and times, so they match what the device computes.

use core::fmt;

/// Speed of light used by the SDK \[m/s\].
pub const SPEED_OF_LIGHT: f64 = 3.0e8;

/// One non-empty line of a .cfg file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CfgLine<'a> {
    /// 1-based line number in the file.
    pub line_no: u32,
    /// The line without surrounding whitespace.
    pub text: &'a str,
}

impl<'a> CfgLine<'a> {
    /// True for `%` comments (the device answers them `Skipped`).
    pub fn is_comment(&self) -> bool {
        self.text.starts_with('%')
    }
    /// The command word (first token).
    pub fn command(&self) -> &'a str {
        self.text.split_whitespace().next().unwrap_or("")
    }
}

/// The non-empty lines of a .cfg text, comments included, with their line numbers.
pub fn lines(text: &str) -> impl Iterator<Item = CfgLine<'_>> {
    text.lines().enumerate().filter_map(|(i, l)| {
        let t = l.trim();
        (!t.is_empty()).then_some(CfgLine {
            line_no: i as u32 + 1,
            text: t,
        })
    })
}

/// Why a .cfg line could not be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CfgError {
    /// 1-based line number (0 when the problem is a missing command).
    pub line_no: u32,
    /// What is wrong.
    pub kind: CfgErrorKind,
}

/// What is wrong with a .cfg.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CfgErrorKind {
    /// A command has fewer arguments than it needs.
    MissingArgs {
        /// Command.
        cmd: &'static str,
        /// Arguments needed.
        need: u8,
        /// Arguments present.
        got: u8,
    },
    /// An argument is not a number of the right kind.
    BadNumber {
        /// Command.
        cmd: &'static str,
        /// 1-based argument position.
        arg: u8,
    },
    /// A command the derived quantities need is absent.
    Missing {
        /// Command.
        cmd: &'static str,
    },
    /// More chirpCfg lines than this parser keeps.
    TooManyChirps {
        /// The limit.
        max: u8,
    },
    /// The values cannot describe a working chirp (zero slope, empty chirp range, ...).
    Invalid {
        /// What.
        what: &'static str,
    },
}

impl fmt::Display for CfgError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line_no > 0 {
            write!(f, "line {}: ", self.line_no)?;
        }
        match self.kind {
            CfgErrorKind::MissingArgs { cmd, need, got } => {
                write!(f, "{cmd} needs {need} arguments, got {got}")
            }
            CfgErrorKind::BadNumber { cmd, arg } => {
                write!(f, "{cmd}: argument {arg} is not a valid number")
            }
            CfgErrorKind::Missing { cmd } => write!(f, "no {cmd} command in the configuration"),
            CfgErrorKind::TooManyChirps { max } => write!(f, "more than {max} chirpCfg lines"),
            CfgErrorKind::Invalid { what } => write!(f, "invalid configuration: {what}"),
        }
    }
}

impl core::error::Error for CfgError {}

/// profileCfg, as written (before the device quantises it).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ProfileCfg {
    /// Profile id.
    pub id: u8,
    /// Start frequency \[GHz\].
    pub start_freq_ghz: f64,
    /// Idle time \[us\].
    pub idle_time_us: f64,
    /// ADC start time \[us\].
    pub adc_start_time_us: f64,
    /// Ramp end time \[us\].
    pub ramp_end_time_us: f64,
    /// Frequency slope \[MHz/us\].
    pub freq_slope_mhz_us: f64,
    /// ADC samples per chirp.
    pub num_adc_samples: u32,
    /// ADC sample rate \[ksps\].
    pub dig_out_sample_rate_ksps: f64,
    /// RX gain \[dB\].
    pub rx_gain_db: f64,
}

/// chirpCfg.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ChirpCfg {
    /// First chirp index this line covers.
    pub start_idx: u16,
    /// Last chirp index this line covers.
    pub end_idx: u16,
    /// Profile id.
    pub profile_id: u8,
    /// TX antennas enabled (bit mask).
    pub tx_mask: u8,
}

/// frameCfg.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameCfg {
    /// First chirp of the frame loop.
    pub chirp_start_idx: u16,
    /// Last chirp of the frame loop.
    pub chirp_end_idx: u16,
    /// Loops per frame.
    pub num_loops: u32,
    /// Frames to send (0 = forever).
    pub num_frames: u32,
    /// Frame period \[ms\].
    pub frame_periodicity_ms: f64,
}

/// guiMonitor: which TLVs the demo sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GuiMonitor {
    /// 0 = none, 1 = points + side info, 2 = points only.
    pub detected_objects: u8,
    /// Range profile (TLV 2).
    pub log_mag_range: bool,
    /// Noise profile (TLV 3).
    pub noise_profile: bool,
    /// Azimuth heatmap (TLV 4).
    pub range_azimuth_heatmap: bool,
    /// Range-Doppler heatmap (TLV 5).
    pub range_doppler_heatmap: bool,
    /// Stats and temperature (TLV 6, 9).
    pub stats: bool,
}

/// One parsed .cfg command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command<'a> {
    /// `% ...`.
    Comment,
    /// `sensorStop`.
    SensorStop,
    /// `sensorStart`.
    SensorStart,
    /// `flushCfg`.
    FlushCfg,
    /// `channelCfg rxMask txMask cascading`.
    Channel {
        /// RX antennas enabled (bit mask).
        rx_mask: u8,
        /// TX antennas enabled (bit mask).
        tx_mask: u8,
    },
    /// `adcCfg numADCBits adcOutputFmt` (format 0 real, 1 complex 1x, 2 complex 2x).
    Adc {
        /// ADC output format.
        output_fmt: u8,
    },
    /// `profileCfg ...`.
    Profile(ProfileCfg),
    /// `chirpCfg ...`.
    Chirp(ChirpCfg),
    /// `frameCfg ...`.
    Frame(FrameCfg),
    /// `guiMonitor subFrameIdx detectedObjects logMagRange noiseProfile rangeAzimuthHeatMap rangeDopplerHeatMap statsInfo`.
    GuiMonitor(GuiMonitor),
    /// `configDataPort baud ackPing`.
    DataPort {
        /// Data UART baud rate \[bit/s\].
        baud: u32,
    },
    /// Anything else: kept and uploaded as written.
    Other {
        /// Command word.
        name: &'a str,
    },
}

struct Args<'a> {
    cmd: &'static str,
    line_no: u32,
    toks: [&'a str; 16],
    n: u8,
}

impl<'a> Args<'a> {
    fn new(cmd: &'static str, line: &CfgLine<'a>, need: u8) -> Result<Self, CfgError> {
        let mut toks = [""; 16];
        let mut n = 0u8;
        for t in line.text.split_whitespace().skip(1) {
            if usize::from(n) < toks.len() {
                toks[usize::from(n)] = t;
            }
            n = n.saturating_add(1);
        }
        if n < need {
            return Err(CfgError {
                line_no: line.line_no,
                kind: CfgErrorKind::MissingArgs { cmd, need, got: n },
            });
        }
        Ok(Args {
            cmd,
            line_no: line.line_no,
            toks,
            n,
        })
    }
    fn err(&self, arg: u8) -> CfgError {
        CfgError {
            line_no: self.line_no,
            kind: CfgErrorKind::BadNumber { cmd: self.cmd, arg },
        }
    }
    fn f(&self, i: u8) -> Result<f64, CfgError> {
        let t = self.toks.get(usize::from(i)).copied().unwrap_or("");
        let t = t.strip_prefix('+').unwrap_or(t);
        t.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| self.err(i + 1))
    }
    fn i(&self, i: u8) -> Result<i64, CfgError> {
        let t = self.toks.get(usize::from(i)).copied().unwrap_or("");
        t.parse::<i64>().map_err(|_| self.err(i + 1))
    }
    fn u<T: TryFrom<i64>>(&self, i: u8) -> Result<T, CfgError> {
        T::try_from(self.i(i)?).map_err(|_| self.err(i + 1))
    }
    fn flag(&self, i: u8) -> Result<bool, CfgError> {
        if i >= self.n {
            return Ok(false);
        }
        Ok(self.i(i)? != 0)
    }
}

/// Parses one line.
pub fn parse_line<'a>(line: &CfgLine<'a>) -> Result<Command<'a>, CfgError> {
    if line.is_comment() {
        return Ok(Command::Comment);
    }
    let name = line.command();
    Ok(match name {
        "sensorStop" => Command::SensorStop,
        "sensorStart" => Command::SensorStart,
        "flushCfg" => Command::FlushCfg,
        "channelCfg" => {
            let a = Args::new("channelCfg", line, 2)?;
            Command::Channel {
                rx_mask: a.u(0)?,
                tx_mask: a.u(1)?,
            }
        }
        "adcCfg" => {
            let a = Args::new("adcCfg", line, 2)?;
            Command::Adc {
                output_fmt: a.u(1)?,
            }
        }
        "profileCfg" => {
            let a = Args::new("profileCfg", line, 14)?;
            Command::Profile(ProfileCfg {
                id: a.u(0)?,
                start_freq_ghz: a.f(1)?,
                idle_time_us: a.f(2)?,
                adc_start_time_us: a.f(3)?,
                ramp_end_time_us: a.f(4)?,
                freq_slope_mhz_us: a.f(7)?,
                num_adc_samples: a.u(9)?,
                dig_out_sample_rate_ksps: a.f(10)?,
                rx_gain_db: a.f(13)?,
            })
        }
        "chirpCfg" => {
            let a = Args::new("chirpCfg", line, 8)?;
            Command::Chirp(ChirpCfg {
                start_idx: a.u(0)?,
                end_idx: a.u(1)?,
                profile_id: a.u(2)?,
                tx_mask: a.u(7)?,
            })
        }
        "frameCfg" => {
            let a = Args::new("frameCfg", line, 5)?;
            Command::Frame(FrameCfg {
                chirp_start_idx: a.u(0)?,
                chirp_end_idx: a.u(1)?,
                num_loops: a.u(2)?,
                num_frames: a.u(3)?,
                frame_periodicity_ms: a.f(4)?,
            })
        }
        "guiMonitor" => {
            let a = Args::new("guiMonitor", line, 7)?;
            Command::GuiMonitor(GuiMonitor {
                detected_objects: a.u(1)?,
                log_mag_range: a.flag(2)?,
                noise_profile: a.flag(3)?,
                range_azimuth_heatmap: a.flag(4)?,
                range_doppler_heatmap: a.flag(5)?,
                stats: a.flag(6)?,
            })
        }
        "configDataPort" => {
            let a = Args::new("configDataPort", line, 1)?;
            Command::DataPort { baud: a.u(0)? }
        }
        _ => Command::Other { name },
    })
}

/// Maximum number of chirpCfg lines kept.
pub const MAX_CHIRPS: usize = 32;

/// The chirp configuration of a .cfg file (the commands the derived quantities need).
#[derive(Debug, Clone, PartialEq)]
pub struct RadarConfig {
    /// profileCfg (the first one; the demo uses a single profile).
    pub profile: Option<ProfileCfg>,
    /// chirpCfg lines.
    pub chirps: heapless::Vec<ChirpCfg, MAX_CHIRPS>,
    /// frameCfg.
    pub frame: Option<FrameCfg>,
    /// channelCfg (rx mask, tx mask).
    pub channel: Option<(u8, u8)>,
    /// adcCfg output format.
    pub adc_output_fmt: Option<u8>,
    /// guiMonitor.
    pub gui: Option<GuiMonitor>,
    /// Data port baud rate from configDataPort \[bit/s\].
    pub data_baud: Option<u32>,
    /// Sub-frames per frame: `numOfSubFrames` of advFrameCfg (advanced frame configuration), 1
    /// without it.
    pub num_subframes: u8,
    /// extendedMaxVelocity enabled for some sub-frame (the demo then unfolds radial velocities up
    /// to twice the unambiguous maximum).
    pub extended_max_velocity: bool,
    /// Commands kept but not modelled (tracking, monitoring, ...).
    pub other_commands: u32,
    /// Comment lines.
    pub comments: u32,
}

/// RF quantisation scale of the device family.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RfScale {
    /// 76-81 GHz parts (xWR14xx/16xx/18xx): 3.6.
    Ghz77,
    /// 60-64 GHz parts (xWR68xx/64xx): 2.7.
    Ghz60,
}

impl RfScale {
    /// The scale factor.
    pub fn factor(self) -> f64 {
        match self {
            RfScale::Ghz77 => 3.6,
            RfScale::Ghz60 => 2.7,
        }
    }
    /// The family a start frequency belongs to (below 70 GHz: the 60 GHz parts).
    pub fn for_start_freq(ghz: f64) -> RfScale {
        if ghz < 70.0 {
            RfScale::Ghz60
        } else {
            RfScale::Ghz77
        }
    }
}

/// What a chirp configuration implies, as the device computes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Derived {
    /// RF scale used.
    pub rf_scale: f64,
    /// Slope after the CLI's int16 quantisation \[MHz/us\].
    pub slope_mhz_us: f64,
    /// Start frequency after quantisation \[GHz\].
    pub start_freq_ghz: f64,
    /// Chirp centre frequency over the sampled part of the ramp \[GHz\].
    pub center_freq_ghz: f64,
    /// Sampled bandwidth \[MHz\].
    pub sampled_bandwidth_mhz: f64,
    /// Range FFT size.
    pub num_range_bins: u32,
    /// Doppler FFT size.
    pub num_doppler_bins: u32,
    /// Chirps per frame (all TX).
    pub chirps_per_frame: u32,
    /// TX antennas in the TDM loop.
    pub num_tx: u32,
    /// RX antennas.
    pub num_rx: u32,
    /// Range bin size \[m\].
    pub range_resolution_m: f64,
    /// Largest range the IF bandwidth allows \[m\] (c fs / 2S, halved for real ADC output).
    pub max_range_m: f64,
    /// Doppler bin size \[m/s\].
    pub velocity_resolution_mps: f64,
    /// Largest unambiguous radial speed \[m/s\].
    pub max_velocity_mps: f64,
    /// Time the chirps of one frame take: chirps x (idle + ramp end) \[ms\].
    pub active_frame_time_ms: f64,
    /// Frame period after quantisation to 5 ns \[ms\].
    pub frame_period_ms: f64,
    /// Data UART rate \[bit/s\] (921600 unless configDataPort says otherwise).
    pub data_baud: u32,
    /// Bytes per frame the data UART carries at that rate and frame period \[B\].
    pub uart_bytes_per_frame: u32,
    /// Bytes per frame of everything except points (header, TLV headers, profiles, stats,
    /// padding) \[B\].
    pub fixed_bytes_per_frame: u32,
    /// Bytes per point (16, plus 4 with side info) \[B\].
    pub bytes_per_point: u32,
    /// Points per frame the UART can carry before frames start to back up.
    pub max_points_per_frame: u32,
    /// Sub-frames per frame (advFrameCfg; 1 without it).
    pub num_subframes: u32,
    /// extendedMaxVelocity is enabled: radial velocities may reach twice
    /// [`Derived::max_velocity_mps`].
    pub extended_max_velocity: bool,
}

impl RadarConfig {
    /// Parses a whole .cfg text. Unknown commands are counted and kept going past.
    pub fn parse(text: &str) -> Result<RadarConfig, CfgError> {
        let mut c = RadarConfig {
            profile: None,
            chirps: heapless::Vec::new(),
            frame: None,
            channel: None,
            adc_output_fmt: None,
            gui: None,
            data_baud: None,
            num_subframes: 1,
            extended_max_velocity: false,
            other_commands: 0,
            comments: 0,
        };
        for line in lines(text) {
            match parse_line(&line)? {
                Command::Comment => c.comments += 1,
                Command::Profile(p) => {
                    if c.profile.is_none() {
                        c.profile = Some(p);
                    }
                }
                Command::Chirp(ch) => c.chirps.push(ch).map_err(|_| CfgError {
                    line_no: line.line_no,
                    kind: CfgErrorKind::TooManyChirps {
                        max: MAX_CHIRPS as u8,
                    },
                })?,
                Command::Frame(f) => c.frame = Some(f),
                Command::Channel { rx_mask, tx_mask } => c.channel = Some((rx_mask, tx_mask)),
                Command::Adc { output_fmt } => c.adc_output_fmt = Some(output_fmt),
                Command::GuiMonitor(g) => c.gui = Some(g),
                Command::DataPort { baud } => c.data_baud = Some(baud),
                Command::Other { name } => {
                    c.other_commands += 1;
                    match name {
                        // advFrameCfg numOfSubFrames forceProfile numFrames triggerSelect frameTrigDelay
                        "advFrameCfg" => {
                            let a = Args::new("advFrameCfg", &line, 1)?;
                            c.num_subframes = a.u::<u8>(0)?.max(1);
                        }
                        // extendedMaxVelocity subFrameIdx enabled
                        "extendedMaxVelocity" => {
                            let a = Args::new("extendedMaxVelocity", &line, 2)?;
                            c.extended_max_velocity |= a.flag(1)?;
                        }
                        _ => {}
                    }
                }
                Command::SensorStop | Command::SensorStart | Command::FlushCfg => {}
            }
        }
        Ok(c)
    }

    /// Derived quantities; `rf` defaults to the family the start frequency implies.
    pub fn derive(&self, rf: Option<RfScale>) -> Result<Derived, CfgError> {
        let missing = |cmd| CfgError {
            line_no: 0,
            kind: CfgErrorKind::Missing { cmd },
        };
        let invalid = |what| CfgError {
            line_no: 0,
            kind: CfgErrorKind::Invalid { what },
        };
        let p = self.profile.ok_or(missing("profileCfg"))?;
        let fr = self.frame.ok_or(missing("frameCfg"))?;
        let scale = rf
            .unwrap_or(RfScale::for_start_freq(p.start_freq_ghz))
            .factor();
        let two26 = f64::from(1u32 << 26);

        // The CLI's quantisation (truncation towards zero, as the C casts do).
        let slope_lsb = scale * 1e3 * 900.0 / two26; // [MHz/us] (48.279 kHz/us at 77 GHz)
        let slope_q = libm::trunc(p.freq_slope_mhz_us / slope_lsb);
        if !(1.0..=32767.0).contains(&slope_q) {
            return Err(invalid(
                "frequency slope must be positive and fit the int16 register",
            ));
        }
        let slope = slope_q * slope_lsb; // [MHz/us]
        let start = libm::trunc(p.start_freq_ghz * two26 / scale) * scale / two26; // [GHz]
        let q10ns = |us: f64| libm::trunc(us * 1000.0 / 10.0) * 10.0 / 1000.0;
        let (idle, adc_start, ramp_end) = (
            q10ns(p.idle_time_us),
            q10ns(p.adc_start_time_us),
            q10ns(p.ramp_end_time_us),
        );
        let period_ms = libm::trunc(fr.frame_periodicity_ms * 1e6 / 5.0) * 5.0 / 1e6;

        if p.num_adc_samples == 0 || p.dig_out_sample_rate_ksps <= 0.0 {
            return Err(invalid(
                "numAdcSamples and digOutSampleRate must be positive",
            ));
        }
        if fr.chirp_end_idx < fr.chirp_start_idx || fr.num_loops == 0 {
            return Err(invalid("frameCfg chirp range is empty or numLoops is 0"));
        }
        let num_range_bins = p
            .num_adc_samples
            .checked_next_power_of_two()
            .ok_or(invalid("numAdcSamples too large"))?;
        let loop_chirps = u32::from(fr.chirp_end_idx - fr.chirp_start_idx) + 1;
        let chirps_per_frame = loop_chirps.saturating_mul(fr.num_loops);
        let tx_union = self
            .chirps
            .iter()
            .filter(|c| c.end_idx >= fr.chirp_start_idx && c.start_idx <= fr.chirp_end_idx)
            .fold(0u8, |m, c| m | c.tx_mask);
        let num_tx = if tx_union == 0 {
            loop_chirps
        } else {
            tx_union.count_ones()
        }
        .max(1);
        let num_rx = self.channel.map_or(0, |(rx, _)| rx.count_ones());
        let num_doppler_bins = (chirps_per_frame / num_tx).max(1).next_power_of_two();

        let fs = p.dig_out_sample_rate_ksps * 1e3; // [sps]
        let s_hz_per_s = slope * 1e12;
        let if_max_range = SPEED_OF_LIGHT * fs / (2.0 * s_hz_per_s);
        let range_resolution_m = if_max_range / f64::from(num_range_bins);
        let real_adc = self.adc_output_fmt == Some(0);
        let max_range_m = if real_adc {
            if_max_range / 2.0
        } else {
            if_max_range
        };
        let sampled_bw_mhz = slope * f64::from(p.num_adc_samples) / (fs / 1e6);
        let fc_ghz = start + (slope * adc_start) / 1e3 + sampled_bw_mhz / 2.0 / 1e3;
        let tc_s = (idle + ramp_end) * 1e-6;
        let velocity_resolution_mps = SPEED_OF_LIGHT
            / (2.0 * f64::from(num_doppler_bins) * f64::from(num_tx) * fc_ghz * 1e9 * tc_s);
        let max_velocity_mps = velocity_resolution_mps * f64::from(num_doppler_bins) / 2.0;

        let data_baud = self.data_baud.unwrap_or(921_600);
        let uart_bytes_per_frame = (f64::from(data_baud) / 10.0 * period_ms / 1e3) as u32;
        let gui = self.gui.unwrap_or(GuiMonitor {
            detected_objects: 1,
            ..GuiMonitor::default()
        });
        let side_info = gui.detected_objects == 1;
        let bytes_per_point = if side_info { 20 } else { 16 };
        let profile_bytes = num_range_bins * 2 + 8;
        let mut fixed = 40 + 8 + if side_info { 8 } else { 0 } + 31;
        if gui.log_mag_range {
            fixed += profile_bytes;
        }
        if gui.noise_profile {
            fixed += profile_bytes;
        }
        if gui.stats {
            fixed += 8 + 24 + 8 + 28;
        }
        let max_points_per_frame = uart_bytes_per_frame.saturating_sub(fixed) / bytes_per_point;
        Ok(Derived {
            rf_scale: scale,
            slope_mhz_us: slope,
            start_freq_ghz: start,
            center_freq_ghz: fc_ghz,
            sampled_bandwidth_mhz: sampled_bw_mhz,
            num_range_bins,
            num_doppler_bins,
            chirps_per_frame,
            num_tx,
            num_rx,
            range_resolution_m,
            max_range_m,
            velocity_resolution_mps,
            max_velocity_mps,
            active_frame_time_ms: f64::from(chirps_per_frame) * (idle + ramp_end) / 1e3,
            frame_period_ms: period_ms,
            data_baud,
            uart_bytes_per_frame,
            fixed_bytes_per_frame: fixed,
            bytes_per_point,
            max_points_per_frame,
            num_subframes: u32::from(self.num_subframes.max(1)),
            extended_max_velocity: self.extended_max_velocity,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CFG: &str = "% comment\nsensorStop\nflushCfg\ndfeDataOutputMode 1\nchannelCfg 15 7 0\nadcCfg 2 1\n\
        profileCfg 0 77 7 3 39 0 0 100 1 256 7200 0 0 30\nchirpCfg 0 0 0 0 0 0 0 1\nchirpCfg 1 1 0 0 0 0 0 4\n\
        chirpCfg 2 2 0 0 0 0 0 2\nframeCfg 0 2 16 0 100 1 0\nguiMonitor -1 1 1 0 0 0 1\ntrackingCfg 1 2 3\nsensorStart\n";

    #[test]
    fn parses_and_keeps_unknown_commands() {
        let c = RadarConfig::parse(CFG).unwrap();
        assert_eq!(c.chirps.len(), 3);
        assert_eq!(
            c.other_commands, 2,
            "dfeDataOutputMode and trackingCfg are kept as Other"
        );
        assert_eq!(c.comments, 1);
        assert_eq!(c.channel, Some((15, 7)));
        assert_eq!((c.num_subframes, c.extended_max_velocity), (1, false));
    }

    #[test]
    fn advanced_frame_and_extended_velocity_are_recorded() {
        let text = format!("{CFG}advFrameCfg 2 0 0 1 0\nextendedMaxVelocity -1 1\n");
        let c = RadarConfig::parse(&text).unwrap();
        assert_eq!((c.num_subframes, c.extended_max_velocity), (2, true));
        let d = c.derive(None).unwrap();
        assert_eq!((d.num_subframes, d.extended_max_velocity), (2, true));
        let c = RadarConfig::parse("extendedMaxVelocity -1 0\n").unwrap();
        assert!(!c.extended_max_velocity);
        assert!(RadarConfig::parse("advFrameCfg x").is_err());
    }

    #[test]
    fn derived_quantities_follow_the_rfparser() {
        let d = RadarConfig::parse(CFG).unwrap().derive(None).unwrap();
        assert_eq!((d.num_range_bins, d.num_tx, d.num_rx), (256, 3, 4));
        assert_eq!((d.chirps_per_frame, d.num_doppler_bins), (48, 16));
        // 100 MHz/us on a 77 GHz part: 100e3 / 48.279 = 2071.3 -> 2071 LSB.
        let lsb = 3.6e3 * 900.0 / f64::from(1u32 << 26);
        assert!((d.slope_mhz_us - 2071.0 * lsb).abs() < 1e-12);
        let expect_rr = 3e8 * 7.2e6 / (2.0 * d.slope_mhz_us * 1e12 * 256.0);
        assert!((d.range_resolution_m - expect_rr).abs() < 1e-12);
        assert!(
            (d.range_resolution_m - 0.0422).abs() < 1e-3,
            "{}",
            d.range_resolution_m
        );
        assert!((d.frame_period_ms - 100.0).abs() < 1e-9);
        // fc = 77 GHz + S * 3 us + S * (256 / 7.2 Msps) / 2; Tc = 7 + 39 us; 3 TX, 16 Doppler bins.
        let fc = 77.0 + d.slope_mhz_us * 3.0 / 1e3 + d.slope_mhz_us * 256.0 / 7.2 / 2.0 / 1e3;
        assert!(
            (d.center_freq_ghz - fc).abs() < 1e-6,
            "{} vs {fc}",
            d.center_freq_ghz
        );
        let vres = 3e8 / (2.0 * 16.0 * 3.0 * fc * 1e9 * 46e-6);
        assert!((d.velocity_resolution_mps - vres).abs() < 1e-9);
        assert!(
            (d.velocity_resolution_mps - 0.859).abs() < 0.01,
            "{}",
            d.velocity_resolution_mps
        );
        assert!((d.max_velocity_mps - d.velocity_resolution_mps * 8.0).abs() < 1e-12);
        // 921600 baud, 100 ms: 9216 B per frame.
        assert_eq!(d.uart_bytes_per_frame, 9216);
        assert_eq!(
            d.max_points_per_frame,
            (9216 - d.fixed_bytes_per_frame) / 20
        );
    }

    #[test]
    fn slope_quantisation_on_each_family() {
        let q = |slope: f64, rf| {
            let cfg = format!(
                "profileCfg 0 60 7 3 39 0 0 {slope} 1 256 7200 0 0 30\nframeCfg 0 0 16 0 100 1 0"
            );
            RadarConfig::parse(&cfg)
                .unwrap()
                .derive(Some(rf))
                .unwrap()
                .slope_mhz_us
        };
        // 70 MHz/us is 1449.9 LSB at 77 GHz and 1933.2 LSB at 60 GHz; the CLI truncates.
        let two26 = f64::from(1u32 << 26);
        assert!((q(70.0, RfScale::Ghz77) - 1449.0 * 3.6e3 * 900.0 / two26).abs() < 1e-9);
        assert!((q(70.0, RfScale::Ghz60) - 1933.0 * 2.7e3 * 900.0 / two26).abs() < 1e-9);
        assert!((q(70.0, RfScale::Ghz77) - 69.957).abs() < 1e-3);
    }

    #[test]
    fn errors_name_line_and_argument() {
        let e = RadarConfig::parse("sensorStop\nprofileCfg 0 77 x 3 39 0 0 100 1 256 7200 0 0 30")
            .unwrap_err();
        assert_eq!(
            e,
            CfgError {
                line_no: 2,
                kind: CfgErrorKind::BadNumber {
                    cmd: "profileCfg",
                    arg: 3
                }
            }
        );
        let e = RadarConfig::parse("frameCfg 0 2").unwrap_err();
        assert!(matches!(
            e.kind,
            CfgErrorKind::MissingArgs {
                cmd: "frameCfg",
                need: 5,
                got: 2
            }
        ));
        let e = RadarConfig::parse("sensorStop")
            .unwrap()
            .derive(None)
            .unwrap_err();
        assert_eq!(e.kind, CfgErrorKind::Missing { cmd: "profileCfg" });
    }
}
