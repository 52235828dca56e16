//! Radar scans from `sensor_msgs/PointCloud2`: which fields hold position, Doppler and SNR
//! (matched by name, since drivers differ), and the points in the session's radar axes.
//!
//! Axes: ROS radar frames are x forward (boresight), y left, z up; the session's radar axes are
//! TI's, x right, y boresight, z up. So `x_ti = -y_ros`, `y_ti = x_ros`, `z_ti = z_ros`. Doppler is
//! TI's radial velocity: positive = the target moves away from the sensor.

use crate::ros::msgs::datatype;
use crate::ros::{PointCloud2, PointField};
use std::fmt;

/// Names drivers give the radial velocity, in order of preference.
pub const DOPPLER_NAMES: &[&str] = &["velocity", "doppler", "v", "radial_velocity", "vel"];
/// Names drivers give the return strength, in order of preference.
pub const SNR_NAMES: &[&str] = &["snr", "intensity", "power", "rcs"];

/// The axes a scan's points are in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RadarAxes {
    /// ROS convention (x forward, y left, z up): converted.
    Ros,
    /// Already the session's (TI's) axes: x right, y boresight, z up (what `export-mcap` writes).
    Session,
}

impl RadarAxes {
    /// A point `[x, y, z]` in these axes -> the session's radar axes.
    pub fn to_session(self, p: [f64; 3]) -> [f64; 3] {
        match self {
            RadarAxes::Ros => [-p[1], p[0], p[2]],
            RadarAxes::Session => p,
        }
    }
}

/// Why a scan's layout cannot be used.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LayoutError {
    /// A required field is missing.
    Missing {
        /// What was looked for (`x`, or the Doppler names).
        what: String,
        /// The fields the message has.
        have: Vec<String>,
    },
    /// A field has an unknown datatype or more than one value.
    BadField {
        /// The field.
        name: String,
        /// Its datatype code.
        datatype: u8,
        /// Its count.
        count: u32,
    },
    /// A field does not fit in a point, or the data is not `height * width * point_step` bytes.
    Size {
        /// What is wrong.
        why: String,
    },
}

impl fmt::Display for LayoutError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LayoutError::Missing { what, have } => {
                write!(f, "no field {what} (fields: {})", have.join(", "))
            }
            LayoutError::BadField {
                name,
                datatype,
                count,
            } => write!(
                f,
                "field {name}: datatype {datatype} with count {count} is not a number"
            ),
            LayoutError::Size { why } => f.write_str(why),
        }
    }
}

impl std::error::Error for LayoutError {}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Slot {
    offset: usize,
    datatype: u8,
}

/// Where a scan's values are, found once per layout.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PointLayout {
    xyz: [Slot; 3],
    doppler: Slot,
    snr: Option<Slot>,
    /// The Doppler field's name.
    pub doppler_name: String,
    /// The SNR/intensity field's name, if any.
    pub snr_name: Option<String>,
    /// Bytes of a point the slots need: the end of the furthest slot \[B\].
    needs: usize,
}

/// One point: position in the message's axes \[m\], radial velocity \[m/s\], SNR or intensity
/// (the driver's unit, usually dB) when the scan has one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanPoint {
    /// Position \[m\] in the message's axes.
    pub xyz: [f64; 3],
    /// Radial velocity \[m/s\] (positive away).
    pub doppler: f64,
    /// SNR / intensity.
    pub snr: Option<f64>,
}

impl PointLayout {
    /// Finds the fields of `fields` (position `x, y, z`; Doppler and SNR by [`DOPPLER_NAMES`] and
    /// [`SNR_NAMES`], or by `doppler_field` when given).
    pub fn new(
        fields: &[PointField],
        point_step: u32,
        doppler_field: Option<&str>,
    ) -> Result<PointLayout, LayoutError> {
        let have = || fields.iter().map(|f| f.name.clone()).collect::<Vec<_>>();
        let slot = |f: &PointField| -> Result<Slot, LayoutError> {
            let size = datatype::size(f.datatype)
                .filter(|_| f.count == 1)
                .ok_or_else(|| LayoutError::BadField {
                    name: f.name.clone(),
                    datatype: f.datatype,
                    count: f.count,
                })?;
            if f.offset as usize + size > point_step as usize {
                return Err(LayoutError::Size {
                    why: format!(
                        "field {} at offset {} ({size} B) does not fit a {point_step}-byte point",
                        f.name, f.offset
                    ),
                });
            }
            Ok(Slot {
                offset: f.offset as usize,
                datatype: f.datatype,
            })
        };
        let find = |names: &[&str]| {
            names
                .iter()
                .find_map(|n| fields.iter().find(|f| f.name.eq_ignore_ascii_case(n)))
        };
        let mut xyz = [Slot {
            offset: 0,
            datatype: 0,
        }; 3];
        for (i, n) in ["x", "y", "z"].iter().enumerate() {
            let f = find(&[n]).ok_or_else(|| LayoutError::Missing {
                what: (*n).into(),
                have: have(),
            })?;
            xyz[i] = slot(f)?;
        }
        let doppler_names: Vec<&str> = doppler_field.map_or(DOPPLER_NAMES.to_vec(), |d| vec![d]);
        let d = find(&doppler_names).ok_or_else(|| LayoutError::Missing {
            what: format!("for the Doppler velocity ({})", doppler_names.join(" / ")),
            have: have(),
        })?;
        let snr = find(SNR_NAMES);
        let doppler = slot(d)?;
        let snr_slot = snr.map(slot).transpose()?;
        let needs = xyz
            .iter()
            .chain([&doppler])
            .chain(snr_slot.as_ref())
            .map(|s| s.offset + datatype::size(s.datatype).unwrap_or(8))
            .max()
            .unwrap_or(0);
        Ok(PointLayout {
            xyz,
            doppler,
            snr: snr_slot,
            doppler_name: d.name.clone(),
            snr_name: snr.map(|f| f.name.clone()),
            needs,
        })
    }

    /// The layout of `cloud` (see [`PointLayout::new`]).
    pub fn of(
        cloud: &PointCloud2,
        doppler_field: Option<&str>,
    ) -> Result<PointLayout, LayoutError> {
        PointLayout::new(&cloud.fields, cloud.point_step, doppler_field)
    }

    /// Calls `f` on every point of `cloud`, in order (rows, then columns).
    pub fn points(
        &self,
        cloud: &PointCloud2,
        mut f: impl FnMut(ScanPoint),
    ) -> Result<(), LayoutError> {
        let step = cloud.point_step as usize;
        let row = cloud.row_step as usize;
        // In u128: height, width and the steps are u32 each, so no product can overflow.
        let (h, w) = (u128::from(cloud.height), u128::from(cloud.width));
        let (step128, row128) = (step as u128, row as u128);
        let n = h * w;
        let need = if cloud.height <= 1 {
            n * step128
        } else {
            (h - 1) * row128 + w * step128
        };
        if step < self.needs {
            return Err(LayoutError::Size {
                why: format!(
                    "{step}-byte points, the layout's fields need {} B",
                    self.needs
                ),
            });
        }
        if step == 0 && n > 0
            || need > cloud.data.len() as u128
            || (cloud.height > 1 && row128 < step128 * w)
        {
            return Err(LayoutError::Size {
                why: format!(
                    "{} x {} points of {step} B (row_step {row}) do not fit {} B of data",
                    cloud.height,
                    cloud.width,
                    cloud.data.len()
                ),
            });
        }
        let be = cloud.is_bigendian;
        for r in 0..cloud.height as usize {
            for c in 0..cloud.width as usize {
                let base = if cloud.height <= 1 {
                    c * step
                } else {
                    r * row + c * step
                };
                let p = &cloud.data[base..base + step];
                let v = |s: Slot| value(p, s, be);
                f(ScanPoint {
                    xyz: [v(self.xyz[0]), v(self.xyz[1]), v(self.xyz[2])],
                    doppler: v(self.doppler),
                    snr: self.snr.map(v),
                });
            }
        }
        Ok(())
    }
}

/// The value in `p` at `s` (the layout was checked: the slot fits the point).
fn value(p: &[u8], s: Slot, be: bool) -> f64 {
    let b = &p[s.offset..];
    macro_rules! num {
        ($t:ty, $n:literal) => {{
            let mut a = [0u8; $n];
            a.copy_from_slice(&b[..$n]);
            if be {
                <$t>::from_be_bytes(a) as f64
            } else {
                <$t>::from_le_bytes(a) as f64
            }
        }};
    }
    match s.datatype {
        datatype::INT8 => f64::from(b[0] as i8),
        datatype::UINT8 => f64::from(b[0]),
        datatype::INT16 => num!(i16, 2),
        datatype::UINT16 => num!(u16, 2),
        datatype::INT32 => num!(i32, 4),
        datatype::UINT32 => num!(u32, 4),
        datatype::FLOAT32 => num!(f32, 4),
        _ => num!(f64, 8),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros::Header;

    fn field(name: &str, offset: u32, datatype: u8) -> PointField {
        PointField {
            name: name.into(),
            offset,
            datatype,
            count: 1,
        }
    }

    fn cloud(fields: Vec<PointField>, step: u32, pts: &[Vec<u8>]) -> PointCloud2 {
        PointCloud2 {
            header: Header::default(),
            height: 1,
            width: pts.len() as u32,
            fields,
            is_bigendian: false,
            point_step: step,
            row_step: step * pts.len() as u32,
            data: pts.concat(),
            is_dense: true,
        }
    }

    fn f32s(v: &[f32], step: usize) -> Vec<u8> {
        let mut b: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        b.resize(step, 0);
        b
    }

    #[test]
    fn ti_mmwave_rospkg_layout() {
        // x y z intensity velocity, float32, point_step 32 (as ti_mmwave_rospkg writes).
        let fields = vec![
            field("x", 0, datatype::FLOAT32),
            field("y", 4, datatype::FLOAT32),
            field("z", 8, datatype::FLOAT32),
            field("intensity", 16, datatype::FLOAT32),
            field("velocity", 20, datatype::FLOAT32),
        ];
        let mut p = f32s(&[1.0, 2.0, 3.0], 16);
        p.extend(f32s(&[12.5, -0.75], 16));
        let c = cloud(fields, 32, &[p]);
        let l = PointLayout::of(&c, None).unwrap();
        assert_eq!(l.doppler_name, "velocity");
        assert_eq!(l.snr_name.as_deref(), Some("intensity"));
        let mut got = vec![];
        l.points(&c, |p| got.push(p)).unwrap();
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].xyz, [1.0, 2.0, 3.0]);
        assert_eq!(got[0].doppler, -0.75);
        assert_eq!(got[0].snr, Some(12.5));
        assert_eq!(RadarAxes::Ros.to_session(got[0].xyz), [-2.0, 1.0, 3.0]);
    }

    #[test]
    fn other_names_types_and_big_endian() {
        let fields = vec![
            field("x", 0, datatype::FLOAT64),
            field("y", 8, datatype::FLOAT64),
            field("z", 16, datatype::FLOAT64),
            field("doppler", 24, datatype::INT16),
        ];
        let mut p = Vec::new();
        for v in [1.5f64, -2.0, 0.25] {
            p.extend(v.to_be_bytes());
        }
        p.extend((-3i16).to_be_bytes());
        let mut c = cloud(fields, 26, &[p]);
        c.is_bigendian = true;
        let l = PointLayout::of(&c, None).unwrap();
        assert_eq!(l.snr_name, None);
        let mut got = vec![];
        l.points(&c, |p| got.push(p)).unwrap();
        assert_eq!(got[0].xyz, [1.5, -2.0, 0.25]);
        assert_eq!(got[0].doppler, -3.0);
    }

    #[test]
    fn bad_layouts_are_named() {
        let xyz = || {
            vec![
                field("x", 0, datatype::FLOAT32),
                field("y", 4, datatype::FLOAT32),
                field("z", 8, datatype::FLOAT32),
            ]
        };
        let e = PointLayout::new(&xyz(), 12, None).unwrap_err();
        assert!(e.to_string().contains("Doppler"), "{e}");
        assert!(e.to_string().contains("x, y, z"), "{e}");
        let mut f = xyz();
        f.push(field("velocity", 12, 42));
        assert!(matches!(
            PointLayout::new(&f, 16, None).unwrap_err(),
            LayoutError::BadField { datatype: 42, .. }
        ));
        let mut f = xyz();
        f.push(field("velocity", 12, datatype::FLOAT32));
        assert!(matches!(
            PointLayout::new(&f, 14, None).unwrap_err(),
            LayoutError::Size { .. }
        ));
        let e = PointLayout::new(&f[1..], 16, None).unwrap_err();
        assert!(e.to_string().starts_with("no field x"), "{e}");
        // Data shorter than the points claim.
        let l = PointLayout::new(&f, 16, None).unwrap();
        let mut c = cloud(f, 16, &[vec![0; 16]]);
        c.width = 2;
        assert!(l.points(&c, |_| {}).is_err());
        // A later scan with the same fields but shorter points than the layout was made for.
        c.width = 1;
        c.point_step = 8;
        c.row_step = 8;
        let e = l.points(&c, |_| {}).unwrap_err();
        assert!(e.to_string().contains("need 16 B"), "{e}");
        // Sizes whose products overflow 64 bits are refused, not wrapped.
        c.point_step = 16;
        c.height = u32::MAX;
        c.width = u32::MAX;
        c.row_step = u32::MAX;
        assert!(l.points(&c, |_| {}).is_err());
    }
}
