//! Joint positions as CSV: one row per frame.
//!
//! Columns: `frame` (0-based index), `time_s` (seconds after the motion's first frame,
//! `frame / fps`), then `<joint>_x`, `<joint>_y`, `<joint>_z` for the 24 SMPL joints in SMPL
//! order (`pelvis_x, pelvis_y, pelvis_z, left_hip_x, …, right_hand_z`): world positions
//! from forward kinematics, metres, in this project's **Y-up** world. Comma separated, a
//! header row, `\n` line ends, numbers in the shortest form that reads back exactly (f32).

use egoexo_core::SmplMotion;
use egoexo_core::skeleton::JOINT_NAMES;

use crate::{ExportError, Format, frame_time_s, validate};

/// The header row's column names.
pub fn column_names() -> Vec<String> {
    let mut names = vec!["frame".to_string(), "time_s".to_string()];
    for joint in JOINT_NAMES {
        names.extend(["x", "y", "z"].map(|axis| format!("{joint}_{axis}")));
    }
    names
}

/// Writes the joint positions of every frame of `motion` (see the module docs).
pub fn write_csv(motion: &SmplMotion) -> Result<Vec<u8>, ExportError> {
    validate(motion)?;
    let encode = |e: csv::Error| ExportError::Encode { format: Format::Csv, message: e.to_string() };
    let mut writer = csv::WriterBuilder::new().terminator(csv::Terminator::Any(b'\n')).from_writer(Vec::new());
    writer.write_record(column_names()).map_err(encode)?;
    let mut row: Vec<String> = Vec::with_capacity(2 + 3 * JOINT_NAMES.len());
    for (frame, positions) in motion.joint_positions().iter().enumerate() {
        row.clear();
        row.push(frame.to_string());
        row.push(frame_time_s(motion, frame).to_string());
        for p in positions {
            row.extend(p.to_array().map(|v| v.to_string()));
        }
        writer.write_record(&row).map_err(encode)?;
    }
    writer.into_inner().map_err(|e| ExportError::Encode { format: Format::Csv, message: e.to_string() })
}

#[cfg(test)]
mod tests {
    use egoexo_core::skeleton::SmplSkeleton;

    use super::*;
    use crate::test_motion;

    #[test]
    fn rows_are_the_forward_kinematics_positions() {
        let motion = test_motion::motion(12, SmplSkeleton::mean_shape(), None);
        let bytes = write_csv(&motion).unwrap();
        let mut reader = csv::Reader::from_reader(&bytes[..]);
        let header: Vec<String> = reader.headers().unwrap().iter().map(str::to_string).collect();
        assert_eq!(header.len(), 2 + 72);
        assert_eq!(&header[..5], ["frame", "time_s", "pelvis_x", "pelvis_y", "pelvis_z"]);
        assert_eq!(header[2 + 3 * 15 + 1], "head_y");
        assert_eq!(header.last().unwrap(), "right_hand_z");
        let fk = motion.joint_positions();
        let mut rows = 0;
        for (i, record) in reader.records().enumerate() {
            let record = record.unwrap();
            assert_eq!(record[0].parse::<usize>().unwrap(), i);
            let t: f64 = record[1].parse().unwrap();
            assert!((t - i as f64 / 30.0).abs() < 1e-12);
            for j in 0..24 {
                for (axis, expected) in fk[i][j].to_array().into_iter().enumerate() {
                    let v: f32 = record[2 + 3 * j + axis].parse().unwrap();
                    assert_eq!(v, expected, "frame {i} joint {j} axis {axis}");
                }
            }
            rows += 1;
        }
        assert_eq!(rows, 12);
        assert!(String::from_utf8(bytes).unwrap().ends_with('\n'));
    }
}
