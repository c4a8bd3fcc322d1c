//! Named parameters: locals `#<x>` (one set per subroutine level), globals
//! `#<_x>`, the read-only system ones that report interpreter state
//! (`#<_x>`, `#<_metric>`, `#<_coord_system>` …) and `#<_ini[section]key>`.

use crate::block::g;
use crate::canon::{Plane, Units};
use crate::emit::rotate;
use crate::error::{Fault, R};
use crate::interp::{Distance, FeedMode, Interp, NamedParam, Retract, Side, Turning};

/// The system parameters computed from interpreter state, in lookup order.
const LOOKUPS: &[&str] = &[
    "_line",
    "_motion_mode",
    "_plane",
    "_ccomp",
    "_metric",
    "_imperial",
    "_absolute",
    "_incremental",
    "_inverse_time",
    "_units_per_minute",
    "_units_per_rev",
    "_coord_system",
    "_tool_offset",
    "_retract_r_plane",
    "_retract_old_z",
    "_spindle_rpm_mode",
    "_spindle_css_mode",
    "_ijk_absolute_mode",
    "_lathe_diameter_mode",
    "_lathe_radius_mode",
    "_spindle_on",
    "_spindle_cw",
    "_mist",
    "_flood",
    "_speed_override",
    "_feed_override",
    "_adaptive_feed",
    "_feed_hold",
    "_feed",
    "_rpm",
    "_current_tool",
    "_selected_pocket",
    "_current_pocket",
    "_x",
    "_y",
    "_z",
    "_a",
    "_b",
    "_c",
    "_u",
    "_v",
    "_w",
    "_abs_x",
    "_abs_y",
    "_abs_z",
    "_abs_a",
    "_abs_b",
    "_abs_c",
    "_value",
    "_call_level",
    "_remap_level",
    "_selected_tool",
    "_value_returned",
    "_task",
];

impl Interp<'_> {
    /// Define the read-only system parameters.
    pub(crate) fn init_named_parameters(&mut self, version: (f64, f64)) {
        let globals = &mut self.contexts[0].named;
        let fixed = |value| NamedParam {
            value,
            readonly: true,
            unset: false,
            lookup: None,
        };
        globals.insert("_vmajor".into(), fixed(version.0));
        globals.insert("_vminor".into(), fixed(version.1));
        globals.insert("_metric_machine".into(), fixed(self.cfg.metric_machine));
        for (i, name) in LOOKUPS.iter().enumerate() {
            globals.insert(
                (*name).into(),
                NamedParam {
                    value: 0.0,
                    readonly: true,
                    unset: false,
                    lookup: Some(i as u8),
                },
            );
        }
    }

    /// The scope of a named parameter: globals (leading `_`) live at level 0.
    fn scope(&self, name: &str) -> usize {
        if name.starts_with('_') {
            0
        } else {
            self.call_level
        }
    }

    /// The value of a named parameter, `None` if it does not exist.
    pub(crate) fn find_named_param(&mut self, name: &str) -> R<Option<f64>> {
        let level = self.scope(name);
        if let Some(p) = self.contexts[level].named.get(name).copied() {
            return Ok(Some(match p.lookup {
                Some(i) => self.lookup_named_param(i),
                None => p.value,
            }));
        }
        if self.cfg.ini_vars
            && name
                .get(..5)
                .is_some_and(|p| p.eq_ignore_ascii_case("_ini["))
        {
            if let Some(v) = self.fetch_ini_param(name)? {
                self.contexts[0].named.insert(
                    name.to_string(),
                    NamedParam {
                        value: v,
                        readonly: true,
                        unset: false,
                        lookup: None,
                    },
                );
                return Ok(Some(v));
            }
        }
        Ok(None)
    }

    /// `#<_ini[section]key>`: the INI value, names matched in upper case.
    fn fetch_ini_param(&self, name: &str) -> R<Option<f64>> {
        let Some(close) = name.get(6..).and_then(|r| r.find(']')).map(|i| i + 6) else {
            return Ok(None);
        };
        let Some(ini) = &self.cfg.ini else {
            return Ok(None);
        };
        let section = name[5..close].to_ascii_uppercase();
        let key = name[close + 1..].to_ascii_uppercase();
        // A missing entry is an undefined parameter (EXISTS gives 0).
        Ok(ini.get_f64(&section, &key))
    }

    /// Create a named parameter (unset) if it does not exist yet.
    pub(crate) fn add_named_param(&mut self, name: &str, readonly: bool) -> R {
        if self.find_named_param(name)?.is_some() {
            return Ok(());
        }
        let level = self.scope(name);
        self.contexts[level].named.insert(
            name.to_string(),
            NamedParam {
                value: 0.0,
                readonly,
                unset: true,
                lookup: None,
            },
        );
        Ok(())
    }

    /// Assign a named parameter (it must have been added).
    pub(crate) fn store_named_param(
        &mut self,
        name: &str,
        value: f64,
        override_readonly: bool,
    ) -> R {
        let level = self.scope(name);
        match self.contexts[level].named.get_mut(name) {
            None => Err(Fault::new(format!(
                "Internal error: Could not assign #<{name}>"
            ))),
            Some(p) if p.readonly && !override_readonly => Err(Fault::new(format!(
                "Cannot assign to read-only parameter #<{name}>"
            ))),
            Some(p) => {
                p.value = value;
                p.unset = false;
                Ok(())
            }
        }
    }

    fn lookup_named_param(&self, index: u8) -> f64 {
        let b = |v: bool| if v { 1.0 } else { 0.0 };
        match LOOKUPS[index as usize] {
            "_line" => self.sequence_number as f64,
            "_motion_mode" => self.motion_mode as f64,
            "_plane" => {
                (match self.plane {
                    Plane::XY => g::G17,
                    Plane::XZ => g::G18,
                    Plane::YZ => g::G19,
                    Plane::UV => g::G17_1,
                    Plane::UW => g::G18_1,
                    Plane::VW => g::G19_1,
                }) as f64
            }
            "_ccomp" => {
                (match self.cutter_comp_side {
                    Side::Right => g::G42,
                    Side::Left => g::G41,
                    Side::Off => g::G40,
                }) as f64
            }
            "_metric" => b(self.length_units == Units::Mm),
            "_imperial" => b(self.length_units == Units::Inch),
            "_absolute" => b(self.distance_mode == Distance::Absolute),
            "_incremental" => b(self.distance_mode == Distance::Incremental),
            "_inverse_time" => b(self.feed_mode == FeedMode::InverseTime),
            "_units_per_minute" => b(self.feed_mode == FeedMode::UnitsPerMinute),
            "_units_per_rev" => b(self.feed_mode == FeedMode::UnitsPerRevolution),
            "_coord_system" => {
                if self.origin_index < 7 {
                    (530 + 10 * self.origin_index) as f64
                } else {
                    (584 + self.origin_index) as f64
                }
            }
            "_tool_offset" => b(self.tool_offset.iter().any(|&v| v != 0.0)),
            "_retract_r_plane" => b(self.retract_mode == Retract::RPlane),
            "_retract_old_z" => b(self.retract_mode == Retract::OldZ),
            "_spindle_rpm_mode" => b(!self.css_mode),
            "_spindle_css_mode" => b(self.css_mode),
            "_ijk_absolute_mode" => b(self.ijk_distance_mode == Distance::Absolute),
            "_lathe_diameter_mode" => b(self.lathe_diameter_mode),
            "_lathe_radius_mode" => b(!self.lathe_diameter_mode),
            "_spindle_on" => b(self.spindle_turning != Turning::Stopped),
            "_spindle_cw" => b(self.spindle_turning == Turning::Clockwise),
            "_mist" => b(self.mist),
            "_flood" => b(self.flood),
            "_speed_override" => b(self.speed_override),
            "_feed_override" => b(self.feed_override),
            "_adaptive_feed" => b(self.adaptive_feed),
            "_feed_hold" => b(self.feed_hold),
            "_feed" => self.feed_rate,
            "_rpm" => self.speed.abs(),
            "_current_tool" => self.params[5400],
            "_selected_pocket" => {
                if self.tools.random_toolchanger() {
                    self.selected_pocket as f64
                } else {
                    let p = self.tools.get(self.selected_pocket.max(0) as usize).pocket;
                    if p == 0 {
                        -1.0
                    } else {
                        p as f64
                    }
                }
            }
            "_current_pocket" => {
                if self.current_pocket == -1 {
                    -1.0
                } else if self.tools.random_toolchanger() {
                    self.current_pocket as f64
                } else {
                    self.tools.get(self.current_pocket.max(0) as usize).pocket as f64
                }
            }
            "_selected_tool" => self.selected_tool as f64,
            "_x" => self.cur[0],
            "_y" => self.cur[1],
            "_z" => self.cur[2],
            "_a" => self.cur[3],
            "_b" => self.cur[4],
            "_c" => self.cur[5],
            "_u" => self.cur[6],
            "_v" => self.cur[7],
            "_w" => self.cur[8],
            "_abs_x" | "_abs_y" => {
                let (x, y) = rotate(
                    self.cur[0] + self.axis_offset[0],
                    self.cur[1] + self.axis_offset[1],
                    self.rotation_xy,
                );
                if LOOKUPS[index as usize] == "_abs_x" {
                    x + self.origin_offset[0] + self.tool_offset[0]
                } else {
                    y + self.origin_offset[1] + self.tool_offset[1]
                }
            }
            "_abs_z" => self.abs_axis(2),
            "_abs_a" => self.abs_axis(3),
            "_abs_b" => self.abs_axis(4),
            "_abs_c" => self.abs_axis(5),
            "_value" => self.return_value,
            "_value_returned" => b(self.value_returned),
            "_call_level" => self.call_level as f64,
            "_remap_level" => self.remap_blocks.len() as f64,
            "_task" => 0.0,
            _ => 0.0,
        }
    }

    /// The position relative to machine zero (all offsets added), in
    /// program units: #5021–#5029 and `#<_abs_x>` ….
    pub(crate) fn absolute_position(&self) -> [f64; 9] {
        let mut p = [0.0; 9];
        let (x, y) = rotate(
            self.cur[0] + self.axis_offset[0],
            self.cur[1] + self.axis_offset[1],
            self.rotation_xy,
        );
        p[0] = x + self.origin_offset[0] + self.tool_offset[0];
        p[1] = y + self.origin_offset[1] + self.tool_offset[1];
        for i in 2..9 {
            p[i] = self.abs_axis(i);
        }
        p
    }

    fn abs_axis(&self, i: usize) -> f64 {
        self.cur[i] + self.axis_offset[i] + self.origin_offset[i] + self.tool_offset[i]
    }
}
