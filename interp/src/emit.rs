//! The canon layer: program coordinates in, machine coordinates out.
//!
//! The interpreter works in program units relative to the active work
//! offset, as LinuxCNC's does. Every command that describes an offset or a
//! unit change updates [`CanonState`] here and goes out in the stream;
//! every move is converted with the state in force: program units to mm,
//! plus the G92/G52 offset, rotated about the work origin, plus the work
//! offset and the tool length offset (LinuxCNC's order).

use crate::canon::{CanonCmd, Plane, Position, ProbeKind, Units};
use crate::error::{Fault, R};
use crate::interp::{Interp, A, C};

/// Offsets and units as the canon layer knows them, in mm and degrees.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CanonState {
    pub units: Units,
    pub g5x: [f64; 9],
    pub g92: [f64; 9],
    pub rotation: f64,
    pub tool: [f64; 9],
    pub plane: Plane,
}

impl Default for CanonState {
    fn default() -> Self {
        CanonState {
            units: Units::Mm,
            g5x: [0.0; 9],
            g92: [0.0; 9],
            rotation: 0.0,
            tool: [0.0; 9],
            plane: Plane::XY,
        }
    }
}

/// Rotate (x, y) by `degrees` counter-clockwise, as LinuxCNC does.
pub(crate) fn rotate(x: f64, y: f64, degrees: f64) -> (f64, f64) {
    if degrees == 0.0 {
        return (x, y);
    }
    let t = degrees.to_radians();
    let (s, c) = t.sin_cos();
    (x * c - y * s, x * s + y * c)
}

/// `a + b`, except that a zero offset leaves `a` (and its sign) alone.
fn add_offset(a: f64, b: f64) -> f64 {
    if b == 0.0 {
        a
    } else {
        a + b
    }
}

/// `v` rounded to `digits` significant decimal digits.
fn round_significant(v: f64, digits: usize) -> f64 {
    format!("{:.*e}", digits - 1, v).parse().unwrap_or(v)
}

impl CanonState {
    fn scale(&self, axis: usize) -> f64 {
        if (A..=C).contains(&axis) {
            1.0
        } else {
            self.units.mm_per_unit()
        }
    }

    /// Program coordinates (current units, work system) to machine mm.
    ///
    /// A zero offset is skipped rather than added so that a programmed
    /// `-0` stays negative zero (IEEE `-0 + 0` is `+0`): rs274 prints the
    /// sign of zero, and the text formatter can recover it only if it
    /// survives the trip to machine coordinates and back.
    pub fn to_machine(self, p: [f64; 9]) -> Position {
        let mut m = [0.0; 9];
        for i in 0..9 {
            m[i] = add_offset(p[i] * self.scale(i), self.g92[i]);
        }
        let (x, y) = rotate(m[0], m[1], self.rotation);
        m[0] = x;
        m[1] = y;
        for i in 0..9 {
            m[i] = add_offset(add_offset(m[i], self.g5x[i]), self.tool[i]);
        }
        Position::from_array(m)
    }

    /// [`Self::to_machine`] for one axis that rotation does not touch.
    fn axis_to_machine(&self, axis: usize, v: f64) -> f64 {
        let m = add_offset(v * self.scale(axis), self.g92[axis]);
        add_offset(add_offset(m, self.g5x[axis]), self.tool[axis])
    }

    /// Machine mm back to the program coordinates the interpreter held.
    ///
    /// Scaling by 25.4 and adding offsets is not invertible in floating
    /// point: `(x * 25.4 + o - o) / 25.4` can differ from `x` in its last
    /// bits, and when `x` was typed as, say, `1.26515`, those bits decide
    /// whether it prints as 1.2651 or 1.2652. So where the plain inverse
    /// lands within a hair of such a tie, the value is replaced by the
    /// shortest decimal that converts forward to the same machine value:
    /// that is the number the program wrote. X and Y under a rotation are
    /// left as computed.
    pub fn to_program_recovered(self, pos: Position) -> [f64; 9] {
        let mut p = self.to_program(pos);
        let m = pos.to_array();
        for i in 0..9 {
            if i < 2 && self.rotation != 0.0 {
                continue;
            }
            let scaled = (p[i] * 1e4).abs().fract();
            if (scaled - 0.5).abs() > 1e-6 {
                continue;
            }
            if let Some(c) = (1..=17)
                .map(|digits| round_significant(p[i], digits))
                .find(|&c| self.axis_to_machine(i, c) == m[i])
            {
                // Keep the sign of a zero the program wrote as `-0`.
                p[i] = if c == 0.0 { p[i] } else { c };
            }
        }
        p
    }

    /// Machine mm back to program coordinates.
    pub fn to_program(self, pos: Position) -> [f64; 9] {
        let mut m = pos.to_array();
        for i in 0..9 {
            m[i] -= self.g5x[i] + self.tool[i];
        }
        let (x, y) = rotate(m[0], m[1], -self.rotation);
        m[0] = x;
        m[1] = y;
        for i in 0..9 {
            m[i] = (m[i] - self.g92[i]) / self.scale(i);
        }
        m
    }

    /// A program-unit offset vector in mm.
    pub fn offset_to_mm(&self, p: [f64; 9]) -> [f64; 9] {
        let mut m = [0.0; 9];
        for i in 0..9 {
            m[i] = p[i] * self.scale(i);
        }
        m
    }
}

impl Interp<'_> {
    /// Program coordinates to machine coordinates with the offsets in force.
    pub fn program_to_machine(&self, p: [f64; 9]) -> Position {
        self.canon.to_machine(p)
    }

    /// Machine coordinates to program coordinates with the offsets in force.
    pub fn machine_to_program(&self, pos: Position) -> [f64; 9] {
        self.canon.to_program(pos)
    }

    pub fn canon_use_length_units(&mut self, units: Units) {
        self.canon.units = units;
        self.emit(CanonCmd::UseLengthUnits(units));
    }

    pub fn canon_set_g5x_offset(&mut self, index: i32, offset: [f64; 9]) {
        self.canon.g5x = self.canon.offset_to_mm(offset);
        self.emit(CanonCmd::SetG5xOffset {
            index: index as u8,
            offset: Position::from_array(self.canon.g5x),
        });
    }

    pub fn canon_set_g92_offset(&mut self, offset: [f64; 9]) {
        self.canon.g92 = self.canon.offset_to_mm(offset);
        self.emit(CanonCmd::SetG92Offset {
            offset: Position::from_array(self.canon.g92),
        });
    }

    pub fn canon_set_xy_rotation(&mut self, degrees: f64) {
        self.canon.rotation = degrees;
        self.emit(CanonCmd::SetXYRotation { degrees });
    }

    pub fn canon_use_tool_length_offset(&mut self, offset: [f64; 9]) {
        self.canon.tool = self.canon.offset_to_mm(offset);
        self.emit(CanonCmd::UseToolLengthOffset {
            offset: Position::from_array(self.canon.tool),
        });
    }

    pub fn canon_select_plane(&mut self, plane: Plane) {
        self.canon.plane = plane;
        self.emit(CanonCmd::SelectPlane(plane));
    }

    /// A length in program units to mm.
    pub fn len_mm(&self, v: f64) -> f64 {
        v * self.canon.units.mm_per_unit()
    }

    pub fn canon_straight_traverse(&mut self, p: [f64; 9]) {
        let end = self.program_to_machine(p);
        self.emit(CanonCmd::StraightTraverse { end });
    }

    pub fn canon_straight_feed(&mut self, p: [f64; 9]) {
        let end = self.program_to_machine(p);
        self.emit(CanonCmd::StraightFeed { end });
    }

    pub fn canon_straight_probe(&mut self, p: [f64; 9], kind: ProbeKind) {
        let end = self.program_to_machine(p);
        self.probe_start = self.program_to_machine(self.cur);
        self.probe_end = end;
        self.probe_kind = kind;
        self.emit(CanonCmd::StraightProbe { end, kind });
    }

    pub fn canon_rigid_tap(&mut self, p: [f64; 9], scale: f64) {
        let end = self.program_to_machine(p);
        self.emit(CanonCmd::RigidTap { end, scale });
    }

    /// An arc in the active plane, in LinuxCNC's argument order: end and
    /// centre on the plane's first and second axes, rotation, the end on
    /// the normal axis, then A B C U V W.
    #[allow(clippy::too_many_arguments)]
    pub fn canon_arc_feed(
        &mut self,
        first_end: f64,
        second_end: f64,
        first_center: f64,
        second_center: f64,
        rotation: i32,
        axis_end: f64,
        abc: [f64; 3],
        uvw: [f64; 3],
    ) -> R {
        let plane = self.canon.plane;
        let [fa, sa, na] = plane.axes();
        let mut end = [0.0; 9];
        end[3..6].copy_from_slice(&abc);
        end[6..9].copy_from_slice(&uvw);
        end[fa.index()] = first_end;
        end[sa.index()] = second_end;
        end[na.index()] = axis_end;
        // The centre's plane coordinates convert like a point whose other
        // coordinates are the end's.
        let mut center = end;
        center[fa.index()] = first_center;
        center[sa.index()] = second_center;
        if self.canon.rotation != 0.0
            && !matches!(plane, Plane::XY | Plane::UV | Plane::VW | Plane::UW)
        {
            return Err(Fault::new(format!(
                "arcs in the {} plane are not supported while the XY plane is rotated (G10 L2 R)",
                plane.gcode()
            )));
        }
        let end_m = self.program_to_machine(end);
        let center_m = self.program_to_machine(center);
        self.emit(CanonCmd::ArcFeed {
            end: end_m,
            center: [center_m.get(fa), center_m.get(sa)],
            plane,
            turns: rotation,
        });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values typed in an inch program with offsets in force come back from
    /// machine millimetres as the same decimals, ties at the fourth place
    /// and the sign of zero included.
    #[test]
    fn program_coordinates_survive_the_trip_to_machine_and_back() {
        let state = CanonState {
            units: Units::Inch,
            g5x: [1.5, -2.25, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            g92: [0.0, 0.125, 0.3, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ..CanonState::default()
        };
        let typed = [
            -1.26515, 0.00005, 2.34565, -0.45355, 1.0, 0.3, 7.77775, -0.00015,
        ];
        for &v in &typed {
            for axis in 0..3 {
                let mut p = [0.0; 9];
                p[axis] = v;
                let back = state.to_program_recovered(state.to_machine(p));
                assert_eq!(
                    format!("{:.4}", back[axis]),
                    format!("{v:.4}"),
                    "axis {axis}, typed {v}"
                );
            }
        }
        // Negative zero survives where no offset is added (with one, -0 + o
        // and +0 + o are the same machine value).
        let plain = CanonState {
            units: Units::Inch,
            ..CanonState::default()
        };
        let mut p = [0.0; 9];
        p[0] = -0.0;
        let back = plain.to_program_recovered(plain.to_machine(p));
        assert_eq!(format!("{:.4}", back[0]), "-0.0000");
        // Machine coordinates: 1 inch on X is 25.4 mm plus the G5x offset;
        // Y at 0 sits at the sum of the offsets (all held in mm).
        let m = state.to_machine([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert!((m.x - 26.9).abs() < 1e-12);
        assert!((m.y - (-2.125)).abs() < 1e-12);
    }
}
