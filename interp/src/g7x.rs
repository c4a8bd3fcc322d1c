//! Lathe cycles: G76 threading, and G70–G72 (refused).
//!
//! G76 cuts a thread in passes along the drive line from the current point
//! to the programmed Z, each pass deeper than the last, the depth
//! following LinuxCNC's degression formula, optionally along a compound
//! angle and with tapered entry and exit, then spring passes at full depth.
//! Every cutting move is synchronised with the spindle.

use crate::block::Block;
use crate::canon::CanonCmd;
use crate::error::{bail, chk, R};
use crate::interp::{Interp, Side, X, Y, Z};

/// The fixed geometry of one G76 cycle, program units (X as a radius).
struct Thread {
    /// X of the drive line (the start point).
    safe_x: f64,
    start_y: f64,
    start_z: f64,
    /// Z where each pass ends, shifted by the compound angle.
    target_z: f64,
    /// Threads inside a bore (I > 0) cut towards +X.
    boring: bool,
    /// Depth at which the tool clears the work, and full thread height.
    end_depth: f64,
    full_height: f64,
    /// Length of the tapered entry/exit along Z (signed with the cut).
    taper_dist: f64,
    entry_taper: bool,
    exit_taper: bool,
    /// Pitch along the drive line and along the taper (program units/rev).
    pitch: f64,
    taper_pitch: f64,
}

impl Interp<'_> {
    /// G70–G72.
    pub(crate) fn convert_g7x(&mut self, motion: i32, _b: &mut Block) -> R {
        bail!(
            "{}: lathe cycles G70, G71 and G72 are not supported yet",
            crate::interp::gcode_name(motion)
        )
    }

    /// G76 threading from the current point to `end` (program units).
    pub(crate) fn convert_threading_cycle(&mut self, b: &Block, end: [f64; 9]) -> R {
        chk!(
            self.cutter_comp_side != Side::Off,
            "Cannot use G76 threading cycle with cutter radius compensation on"
        );
        let (mut i, mut j, mut k) = (b.or(b'i', 0.0), b.or(b'j', 0.0), b.or(b'k', 0.0));
        chk!(i == 0.0, "In G76, I must not be 0");
        chk!(j <= 0.0, "In G76, J must be greater than 0");
        chk!(k <= j, "In G76, K must be greater than J");
        if self.lathe_diameter_mode {
            i /= 2.0;
            j /= 2.0;
            k /= 2.0;
        }
        let start = self.cur;
        let full_dia_depth = i.abs();
        let cut_increment = j.abs();
        let pitch = b.or(b'p', 0.0);
        let cutting_towards_plus_z = end[Z] > start[Z];
        let mut compound = b.get(b'q').unwrap_or(0.0).to_radians();
        if cutting_towards_plus_z {
            compound = -compound;
        }
        let degression = match b.get(b'r') {
            Some(r) if r >= 1.0 => r,
            _ => 1.0,
        };
        let mut taper_dist = b.or(b'e', 0.0).max(0.0);
        let taper_pitch = if taper_dist > 0.0 {
            pitch * taper_dist.hypot(k.abs()) / taper_dist
        } else {
            pitch
        };
        if cutting_towards_plus_z {
            taper_dist = -taper_dist;
        }
        let flags = b.or(b'l', 0.0).max(0.0) as i32;
        let t = Thread {
            safe_x: start[X],
            start_y: start[Y],
            start_z: start[Z],
            target_z: end[Z] + k.abs() * compound.tan(),
            boring: i > 0.0,
            end_depth: k.abs() + i.abs(),
            full_height: k.abs(),
            taper_dist,
            entry_taper: flags & 1 != 0,
            exit_taper: flags & 2 != 0,
            pitch,
            taper_pitch,
        };
        let spring_cuts = b.get(b'h').unwrap_or(0.0).max(0.0) as u32;

        // Passes deepen until the full depth; the depth of pass n is
        // I + J * n^(1/R).
        let mut pass = 1.0f64;
        let mut depth = i.abs() + j.abs();
        while depth < t.end_depth {
            self.threading_pass(&t, depth, (depth - full_dia_depth) * compound.tan());
            pass += 1.0;
            depth = full_dia_depth + cut_increment * pass.powf(1.0 / degression);
        }
        // At full depth at least once, and again for each spring pass.
        let zoff = (t.end_depth - full_dia_depth) * compound.tan();
        for _ in 0..=spring_cuts {
            self.threading_pass(&t, t.end_depth, zoff);
        }
        let mut p = self.cur;
        p[..3].copy_from_slice(&end[..3]);
        self.canon_straight_traverse(p);
        self.cur[..3].copy_from_slice(&end[..3]);
        Ok(())
    }

    /// One pass at `depth` below the drive line, shifted `zoff` along Z by
    /// the compound angle: back out, in, along (synchronised), out.
    fn threading_pass(&mut self, t: &Thread, depth: f64, zoff: f64) {
        // X at a given depth below the drive line (above it when boring).
        let x_at = |d: f64| {
            if t.boring {
                t.safe_x + d
            } else {
                t.safe_x - d
            }
        };
        let at = |s: &Self, x: f64, z: f64| {
            let mut p = s.cur;
            p[X] = x;
            p[Y] = t.start_y;
            p[Z] = z;
            p
        };
        let clear_x = x_at(depth - t.end_depth);
        let full_x = x_at(depth);
        let shallow_x = x_at(depth - t.full_height);
        let z0 = t.start_z - zoff;
        let z1 = t.target_z - zoff;
        let sync = |s: &mut Self, pitch: f64| {
            let mm_per_rev = s.len_mm(pitch);
            s.emit(CanonCmd::StartSpeedFeedSync {
                spindle: s.active_spindle,
                mm_per_rev,
                velocity_mode: false,
            });
        };
        let p = at(self, clear_x, z0);
        self.canon_straight_traverse(p);
        if t.taper_dist != 0.0 && t.entry_taper {
            self.emit(CanonCmd::DisableFeedOverride);
            sync(self, t.taper_pitch);
            let p = at(self, shallow_x, z0);
            self.canon_straight_feed(p);
            let p = at(self, full_x, z0 - t.taper_dist);
            self.canon_straight_feed(p);
            sync(self, t.pitch);
        } else {
            let p = at(self, full_x, z0);
            self.canon_straight_traverse(p);
            self.emit(CanonCmd::DisableFeedOverride);
            sync(self, t.pitch);
        }
        if t.taper_dist != 0.0 && t.exit_taper {
            let p = at(self, full_x, z1 + t.taper_dist);
            self.canon_straight_feed(p);
            sync(self, t.taper_pitch);
            let p = at(self, shallow_x, z1);
            self.canon_straight_feed(p);
        } else {
            let p = at(self, full_x, z1);
            self.canon_straight_feed(p);
        }
        self.emit(CanonCmd::StopSpeedFeedSync);
        let p = at(self, clear_x, z1);
        self.canon_straight_traverse(p);
        self.emit(CanonCmd::EnableFeedOverride);
    }
}
