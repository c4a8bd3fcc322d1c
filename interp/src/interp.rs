//! The interpreter's state and its read-execute loop.
//!
//! The design follows LinuxCNC's RS274NGC interpreter closely, because
//! programs written for it must run unchanged: positions are kept in
//! program coordinates and program units (as LinuxCNC keeps them), one line
//! is read and then executed at a time, and O-word control flow seeks in
//! the program file instead of holding it in memory. The canon layer
//! ([`crate::emit`]) converts program coordinates to machine millimetres.

use std::collections::{HashMap, VecDeque};
use std::fs::File;
use std::io::{BufRead, BufReader, Cursor, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::block::{g, Block, CallType, OType, SUB_PARAMS};
use crate::canon::{
    BlockNumber, Canon, CanonCmd, MotionMode, Plane, Position, Source, ToolData, Units,
};
use crate::config::{Config, Environment, Offline};
use crate::emit::CanonState;
use crate::error::{Fault, InterpError, R};
use crate::paramfile::PARAMETER_COUNT;

/// Something the interpreter can read program lines from and seek in.
pub trait ProgramSource: BufRead + Seek {}
impl<T: BufRead + Seek> ProgramSource for T {}

/// Indices of the axes in position arrays.
pub(crate) const X: usize = 0;
pub(crate) const Y: usize = 1;
pub(crate) const Z: usize = 2;
pub(crate) const A: usize = 3;
pub(crate) const C: usize = 5;

/// Absolute or incremental (G90/G91, G90.1/G91.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Distance {
    Absolute,
    Incremental,
}

/// Feed rate mode (G93, G94, G95).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum FeedMode {
    InverseTime,
    UnitsPerMinute,
    UnitsPerRevolution,
}

/// Canned cycle retract (G98 old Z, G99 R plane).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Retract {
    OldZ,
    RPlane,
}

/// Cutter compensation side.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Side {
    Off,
    Left,
    Right,
}

/// Spindle direction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Turning {
    Stopped,
    Clockwise,
    CounterClockwise,
}

/// A label of an O-word control structure or subroutine, and where it is.
#[derive(Clone, Debug)]
pub(crate) struct Label {
    pub kind: OType,
    pub file: usize,
    pub offset: u64,
    /// Line number of the line before the label's line (as LinuxCNC keeps it).
    pub sequence_number: u32,
    pub repeat_count: i32,
}

/// A named parameter and its attributes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct NamedParam {
    pub value: f64,
    pub readonly: bool,
    /// Never assigned yet.
    pub unset: bool,
    /// Value computed from interpreter state (`#<_x>` and friends).
    pub lookup: Option<u8>,
}

/// Modal state saved by M70/M73 for M72 to restore.
#[derive(Clone, Debug, Default)]
pub(crate) struct SavedModes {
    pub g: [i32; 17],
    pub m: [i32; 9],
    pub settings: [f64; 5],
}

/// A subroutine call frame.
#[derive(Clone, Debug)]
pub(crate) struct Context {
    /// File, position and line to return to.
    pub file: usize,
    pub position: u64,
    pub sequence_number: u32,
    pub sub_name: Option<String>,
    pub saved_params: [f64; SUB_PARAMS],
    pub named: HashMap<String, NamedParam>,
    pub call_type: CallType,
    pub m98_loop_counter: i32,
    /// M70/M73 saved state: valid, restore on return.
    pub saved: Option<SavedModes>,
    pub restore_on_return: bool,
    /// This frame runs a remap handler.
    pub remap_frame: bool,
}

impl Context {
    fn new() -> Context {
        Context {
            file: 0,
            position: 0,
            sequence_number: 0,
            sub_name: None,
            saved_params: [0.0; SUB_PARAMS],
            named: HashMap::new(),
            call_type: CallType::None,
            m98_loop_counter: -1,
            saved: None,
            restore_on_return: false,
            remap_frame: false,
        }
    }
}

/// An open program file.
pub(crate) struct OpenFile<'a> {
    pub name: Arc<str>,
    pub path: Option<PathBuf>,
    pub reader: Box<dyn ProgramSource + 'a>,
    /// Byte offset of the next line.
    pub pos: u64,
}

/// What reading a line gave.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ReadStatus {
    Ok,
    /// The closing `%` of a program that opened with `%`.
    EndFile,
}

/// What executing a line gave.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ExecStatus {
    Ok,
    /// Program end (M2, M30).
    Exit,
    /// A remapped code's subroutine call was prepared in the executing block.
    Remap,
}

/// A word named in errors, kept cheap on the hot path and spelled out only
/// when an error is reported.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum WordName {
    /// A G-code (times ten).
    G(i32),
    /// An M-code.
    M(i32),
    /// A letter word (lower case).
    Letter(u8),
    /// The O-word of the current block.
    O,
}

/// Most nested subroutine calls (LinuxCNC's limit).
pub(crate) const MAX_CALL_LEVELS: usize = 10;

/// The interpreter state: LinuxCNC's "setup", in program units.
pub(crate) struct Interp<'a> {
    pub cfg: Config,
    pub env: Box<dyn Environment + 'a>,

    // ---- files and lines ----
    pub files: Vec<OpenFile<'a>>,
    pub cur_file: usize,
    /// Line number of the line last read in the current file.
    pub sequence_number: u32,
    /// Lines read in all, for [`Config::line_limit`].
    pub lines_read: u64,
    /// The line just read was longer than LinuxCNC accepts.
    pub line_too_long: bool,
    /// How deeply the value being read is nested (see `read_real_value`).
    pub value_depth: u32,
    /// The line as read, trailing blanks removed.
    pub raw: Vec<u8>,
    /// The line folded: lower case, blanks removed outside comments.
    pub line: Vec<u8>,
    /// 1-based source column of each byte of `line`.
    pub cols: Vec<u32>,
    /// The N word at the start of the raw line, for canon sources.
    pub line_n: Option<BlockNumber>,
    pub line_length: usize,
    pub percent_flag: bool,
    /// The block being executed (blocks[0] in LinuxCNC) and the stack of
    /// blocks whose remapped codes are running.
    pub block: Box<Block>,
    /// A second block to swap in while `block` is worked on (swapping
    /// boxes moves a pointer, not the block).
    pub spare_block: Option<Box<Block>>,
    pub remap_blocks: Vec<Block>,

    // ---- position and offsets (program units) ----
    pub cur: [f64; 9],
    /// Programmed (uncompensated) X Y Z while cutter compensation is on.
    pub program: [f64; 3],
    pub origin_offset: [f64; 9],
    pub axis_offset: [f64; 9],
    pub tool_offset: [f64; 9],
    pub rotation_xy: f64,
    pub origin_index: i32,

    // ---- modes ----
    pub length_units: Units,
    pub distance_mode: Distance,
    pub ijk_distance_mode: Distance,
    pub feed_mode: FeedMode,
    pub feed_rate: f64,
    pub plane: Plane,
    pub motion_mode: i32,
    pub retract_mode: Retract,
    pub control_mode: MotionMode,
    pub tolerance: f64,
    pub naivecam_tolerance: f64,
    pub lathe_diameter_mode: bool,

    // ---- cutter compensation ----
    pub cutter_comp_side: Side,
    pub cutter_comp_radius: f64,
    pub cutter_comp_orientation: i32,
    pub cutter_comp_firstmove: bool,
    pub arc_not_allowed: bool,

    // ---- canned cycles ----
    pub cycle_cc: f64,
    pub cycle_i: f64,
    pub cycle_j: f64,
    pub cycle_k: f64,
    pub cycle_l: i32,
    pub cycle_p: f64,
    pub cycle_q: f64,
    pub cycle_r: f64,
    pub cycle_il: f64,
    pub cycle_il_flag: bool,

    // ---- spindle, coolant, overrides ----
    pub speed: f64,
    pub spindle_turning: Turning,
    pub css_mode: bool,
    pub active_spindle: u32,
    pub mist: bool,
    pub flood: bool,
    pub feed_override: bool,
    pub speed_override: bool,
    pub adaptive_feed: bool,
    pub feed_hold: bool,

    // ---- tools ----
    pub tools: crate::tools::ToolTable,
    pub current_pocket: i32,
    pub selected_pocket: i32,
    pub selected_tool: i32,

    // ---- flags for the next read ----
    pub probe_flag: bool,
    pub probe_start: Position,
    pub probe_end: Position,
    pub probe_kind: crate::canon::ProbeKind,
    pub toolchange_flag: bool,
    pub input_flag: bool,
    pub input_digital: bool,
    pub input_index: u32,
    /// M66 wait mode (L word) and longest wait (Q word, seconds).
    pub input_mode: u8,
    pub input_timeout: f64,

    // ---- parameters ----
    pub params: Box<[f64]>,

    // ---- O-words ----
    pub labels: HashMap<String, Label>,
    pub call_level: usize,
    pub contexts: Vec<Context>,
    pub defining_sub: bool,
    pub sub_name: Option<String>,
    pub skipping_o: Option<String>,
    pub skipping_to_sub: Option<String>,
    pub skipping_start: u32,
    pub executed_if: bool,
    pub doing_break: bool,
    pub doing_continue: bool,
    pub test_value: f64,
    pub return_value: f64,
    pub value_returned: bool,

    // ---- output ----
    pub canon: CanonState,
    pub out: VecDeque<Canon>,
    /// Moves and commands held back by cutter compensation.
    pub queue: Vec<crate::comp::Queued>,
    pub queue_endpoint: Option<[f64; 2]>,
    /// The word being executed, named in errors that do not name their own.
    pub fault_word: Option<(WordName, u32)>,
    /// The text errors show instead of the line read: the call a remapped
    /// code turned into (LinuxCNC reports that text).
    pub line_text_override: Option<String>,
}

/// Version reported by `#<_vmajor>` and `#<_vminor>`. LinuxCNC reads its
/// package version "2.9.0" with `sscanf("%lf%lf")`, which yields 2.9 and
/// 0.0; programs test `_vmajor` against 2.9, so kerf reports the same pair.
const VERSION: (f64, f64) = (2.9, 0.0);

impl<'a> Interp<'a> {
    pub fn new(
        reader: Box<dyn ProgramSource + 'a>,
        name: Arc<str>,
        path: Option<PathBuf>,
        cfg: Config,
        env: Box<dyn Environment + 'a>,
    ) -> Interp<'a> {
        let tools = cfg.tool_table.clone();
        let mut it = Interp {
            env,
            files: vec![OpenFile {
                name,
                path,
                reader,
                pos: 0,
            }],
            cur_file: 0,
            sequence_number: 0,
            lines_read: 0,
            line_too_long: false,
            value_depth: 0,
            raw: Vec::with_capacity(256),
            line: Vec::with_capacity(256),
            cols: Vec::with_capacity(256),
            line_n: None,
            line_length: 0,
            percent_flag: false,
            block: Box::default(),
            spare_block: Some(Box::default()),
            remap_blocks: Vec::new(),
            cur: [0.0; 9],
            program: [0.0; 3],
            origin_offset: [0.0; 9],
            axis_offset: [0.0; 9],
            tool_offset: [0.0; 9],
            rotation_xy: 0.0,
            origin_index: 1,
            length_units: Units::Mm,
            distance_mode: Distance::Absolute,
            ijk_distance_mode: Distance::Incremental,
            feed_mode: FeedMode::UnitsPerMinute,
            feed_rate: 0.0,
            plane: Plane::XY,
            motion_mode: g::G80,
            retract_mode: Retract::RPlane,
            control_mode: MotionMode::Continuous { tolerance: 0.0 },
            tolerance: 0.0,
            naivecam_tolerance: 0.0,
            lathe_diameter_mode: false,
            cutter_comp_side: Side::Off,
            cutter_comp_radius: 0.0,
            cutter_comp_orientation: 0,
            cutter_comp_firstmove: true,
            arc_not_allowed: false,
            cycle_cc: 0.0,
            cycle_i: 0.0,
            cycle_j: 0.0,
            cycle_k: 0.0,
            cycle_l: 0,
            cycle_p: 0.0,
            cycle_q: 0.0,
            cycle_r: 0.0,
            cycle_il: 0.0,
            cycle_il_flag: false,
            speed: 0.0,
            spindle_turning: Turning::Stopped,
            css_mode: false,
            active_spindle: 0,
            mist: false,
            flood: false,
            feed_override: true,
            speed_override: true,
            adaptive_feed: false,
            feed_hold: true,
            tools,
            current_pocket: cfg.spindle_tool_index as i32,
            selected_pocket: 0,
            selected_tool: 0,
            probe_flag: false,
            probe_start: Position::ZERO,
            probe_end: Position::ZERO,
            probe_kind: crate::canon::ProbeKind {
                toward: true,
                error_if_no_trip: true,
            },
            toolchange_flag: false,
            input_flag: false,
            input_digital: false,
            input_index: 0,
            input_mode: 0,
            input_timeout: 0.0,
            params: vec![0.0; PARAMETER_COUNT].into_boxed_slice(),
            labels: HashMap::new(),
            call_level: 0,
            contexts: (0..MAX_CALL_LEVELS).map(|_| Context::new()).collect(),
            defining_sub: false,
            sub_name: None,
            skipping_o: None,
            skipping_to_sub: None,
            skipping_start: 0,
            executed_if: false,
            doing_break: false,
            doing_continue: false,
            test_value: 0.0,
            return_value: 0.0,
            value_returned: false,
            canon: CanonState::default(),
            out: VecDeque::new(),
            queue: Vec::new(),
            queue_endpoint: None,
            fault_word: None,
            line_text_override: None,
            cfg,
        };
        it.init();
        it
    }

    /// LinuxCNC's `init`: restore parameters, select the stored coordinate
    /// system and announce units and offsets.
    fn init(&mut self) {
        for &(n, v) in &self.cfg.parameters {
            if n < PARAMETER_COUNT {
                self.params[n] = v;
            }
        }
        self.emit(CanonCmd::UseLengthUnits(Units::Mm));
        self.canon.units = Units::Mm;
        let mut index = (self.params[5220] + 0.0001) as i32;
        if !(1..=9).contains(&index) {
            index = 1;
            self.params[5220] = 1.0;
        }
        self.origin_index = index;
        let k = 5200 + 20 * index as usize;
        for i in 0..9 {
            self.origin_offset[i] = self.user_to_program(i, self.params[k + 1 + i]);
        }
        self.canon_set_g5x_offset(index, self.origin_offset);
        if self.cfg.disable_g92_persistence {
            for p in 5210..5220 {
                self.params[p] = 0.0;
            }
        }
        if self.params[5210] != 0.0 {
            for i in 0..9 {
                self.axis_offset[i] = self.user_to_program(i, self.params[5211 + i]);
            }
        }
        self.canon_set_g92_offset(self.axis_offset);
        self.rotation_xy = self.params[k + 10];
        self.canon_set_xy_rotation(self.rotation_xy);
        self.params[5599] = 1.0;
        // The start position: where the machine is, in program coordinates.
        self.cur = self.machine_to_program(self.cfg.start_position);
        self.init_tool_parameters();
        self.init_named_parameters(VERSION);
    }

    fn init_tool_parameters(&mut self) {
        if self.tools.random_toolchanger() || self.tools.get(0).tool != -1 {
            self.set_tool_parameters_from(self.tools.get(0));
        } else {
            for p in 5400..=5413 {
                self.params[p] = 0.0;
            }
        }
    }

    /// Copy the tool in the spindle into #5400–#5413.
    pub fn set_tool_parameters(&mut self) {
        let t = self.tools.get(0);
        if !self.tools.random_toolchanger() && t.tool <= 0 {
            for p in 5400..=5413 {
                self.params[p] = 0.0;
            }
            return;
        }
        self.set_tool_parameters_from(t);
    }

    fn set_tool_parameters_from(&mut self, t: ToolData) {
        self.params[5400] = t.tool as f64;
        let o = t.offset.to_array();
        for i in 0..9 {
            self.params[5401 + i] = o[i];
        }
        self.params[5410] = t.diameter;
        self.params[5411] = t.front_angle;
        self.params[5412] = t.back_angle;
        self.params[5413] = t.orientation as f64;
    }

    // ------------------------------------------------------------------
    // units

    /// mm per program unit.
    pub fn unit_mm(&self) -> f64 {
        self.length_units.mm_per_unit()
    }

    /// A parameter value in user units to program units (lengths only;
    /// rotary axes `A..=C` pass through).
    pub fn user_to_program(&self, axis: usize, v: f64) -> f64 {
        if (A..=C).contains(&axis) {
            v
        } else {
            self.user_len_to_program(v)
        }
    }

    /// A length in user units to program units.
    pub fn user_len_to_program(&self, v: f64) -> f64 {
        (v / self.cfg.user_units_per_mm) / self.unit_mm()
    }

    /// A length in program units to user units.
    pub fn program_len_to_user(&self, v: f64) -> f64 {
        (v * self.unit_mm()) * self.cfg.user_units_per_mm
    }

    /// A program-unit value to user units for axis `axis`.
    pub fn program_to_user(&self, axis: usize, v: f64) -> f64 {
        if (A..=C).contains(&axis) {
            v
        } else {
            self.program_len_to_user(v)
        }
    }

    // ------------------------------------------------------------------
    // output

    /// The source of commands made now: the current file, line and N word.
    pub fn source(&self) -> Source {
        Source {
            file: self.files[self.cur_file].name.clone(),
            line: self.sequence_number,
            block: self.line_n,
            reading: self.lines_read,
        }
    }

    /// Give a canon command from the current line.
    pub fn emit(&mut self, cmd: CanonCmd) {
        let source = self.source();
        self.out.push_back(Canon { source, cmd });
    }

    // ------------------------------------------------------------------
    // errors

    /// The spelling of a word for error messages: `G2`, `M3`, `X`, `O100`.
    fn word_name(&self, w: WordName) -> String {
        match w {
            WordName::G(code) => gcode_name(code),
            WordName::M(code) => format!("M{code}"),
            WordName::Letter(l) => (l.to_ascii_uppercase() as char).to_string(),
            // Numbered labels read `O100`; named ones keep their brackets.
            WordName::O if self.block.o_name.bytes().all(|c| c.is_ascii_digit()) => {
                format!("O{}", self.block.o_name)
            }
            WordName::O => format!("O<{}>", self.block.o_name),
        }
    }

    /// Turn a fault into an error located in the current line.
    pub fn locate(&self, f: Fault) -> InterpError {
        let (word, column) = match (f.word, f.column) {
            (Some(w), Some(c)) => (Some(w), c),
            (None, Some(c)) => (None, c),
            (w, None) => match self.fault_word {
                Some((fw, c)) => (w.or_else(|| Some(self.word_name(fw))), c),
                None => (w, 1),
            },
        };
        InterpError {
            file: self.files[self.cur_file].name.clone(),
            // An empty file has no line 0 to point at; its end is line 1.
            line: self.sequence_number.max(1),
            column,
            word,
            message: f.message,
            line_text: self
                .line_text_override
                .clone()
                .unwrap_or_else(|| String::from_utf8_lossy(&self.raw).into_owned()),
        }
    }

    // ------------------------------------------------------------------
    // files

    /// Read the next raw line of the current file into `self.raw`.
    /// Returns false at end of file.
    ///
    /// LinuxCNC reads a line into a 255-byte buffer and refuses one of 254
    /// bytes or more (newline included) as "Command too long". kerf keeps
    /// that limit: programs LinuxCNC runs fit it, and it bounds the memory
    /// a line can take. The rest of a long line is read and dropped, and
    /// `line_too_long` tells [`Interp::read`] to refuse it.
    fn read_raw_line(&mut self) -> R<bool> {
        use std::io::Read;
        const MAX_LINE: u64 = 254;
        self.raw.clear();
        let f = &mut self.files[self.cur_file];
        let name = &f.name;
        let read_err = |e: std::io::Error| Fault::new(format!("cannot read {name}: {e}"));
        let mut n = (&mut f.reader)
            .take(MAX_LINE)
            .read_until(b'\n', &mut self.raw)
            .map_err(read_err)?;
        self.line_too_long = n as u64 >= MAX_LINE;
        if self.line_too_long && self.raw.last() != Some(&b'\n') {
            // Drop the rest of the line, a bounded piece at a time.
            let mut rest = Vec::new();
            loop {
                rest.clear();
                let m = (&mut f.reader)
                    .take(4096)
                    .read_until(b'\n', &mut rest)
                    .map_err(read_err)?;
                n += m;
                if m == 0 || rest.last() == Some(&b'\n') {
                    break;
                }
            }
        }
        if n == 0 {
            return Ok(false);
        }
        f.pos += n as u64;
        while self
            .raw
            .last()
            .is_some_and(|c| matches!(c, b' ' | b'\t' | b'\r' | b'\n' | b'\x0b' | b'\x0c'))
        {
            self.raw.pop();
        }
        Ok(true)
    }

    /// Position of the next line in the current file.
    pub fn tell(&self) -> u64 {
        self.files[self.cur_file].pos
    }

    /// Continue reading file `file` at byte `offset`.
    pub fn seek_to(&mut self, file: usize, offset: u64) -> R {
        self.cur_file = file;
        let f = &mut self.files[file];
        f.reader
            .seek(SeekFrom::Start(offset))
            .map_err(|e| Fault::new(format!("cannot seek in {}: {e}", f.name)))?;
        f.pos = offset;
        Ok(())
    }

    /// Open (or find already open) the program file at `path`.
    pub fn open_file(&mut self, path: &Path) -> R<usize> {
        if let Some(i) = self
            .files
            .iter()
            .position(|f| f.path.as_deref() == Some(path))
        {
            return Ok(i);
        }
        let file = File::open(path)
            .map_err(|_| Fault::new(format!("Unable to open file <{}>", path.display())))?;
        self.files.push(OpenFile {
            name: path.display().to_string().into(),
            path: Some(path.to_path_buf()),
            reader: Box::new(BufReader::with_capacity(16 * 1024, file)),
            pos: 0,
        });
        Ok(self.files.len() - 1)
    }

    /// Find `name.ngc`: next to the main program (LinuxCNC looks in its
    /// working directory, which is the program's folder when it runs a
    /// file), then on the subroutine path.
    pub fn find_ngc_file(&self, name: &str) -> Option<PathBuf> {
        let file = format!("{name}.ngc");
        let here = self.files[0]
            .path
            .as_ref()
            .and_then(|p| p.parent())
            .map(|d| {
                if d.as_os_str().is_empty() {
                    PathBuf::from(".")
                } else {
                    d.to_path_buf()
                }
            });
        here.iter()
            .chain(self.cfg.subroutine_path.iter())
            .map(|d| d.join(&file))
            .find(|p| p.is_file())
    }

    // ------------------------------------------------------------------
    // the read-execute loop

    /// LinuxCNC's `open`: a first line holding only `%` opens a program that
    /// must end with `%`.
    pub fn open_program(&mut self) -> R {
        loop {
            if !self.read_raw_line()? {
                bail!("File ended with no percent sign");
            }
            if !self.raw.is_empty() {
                break;
            }
        }
        if self.raw.trim_ascii_start() == b"%" {
            self.percent_flag = true;
            self.sequence_number = 1;
        } else {
            self.seek_to(0, 0)?;
            self.percent_flag = false;
            self.sequence_number = 0;
        }
        self.raw.clear();
        Ok(())
    }

    /// Read inputs that the last block asked for (probe results, M66, tool
    /// change), as LinuxCNC does before reading the next line.
    fn read_inputs(&mut self) {
        if self.probe_flag {
            self.probe_flag = false;
            let outcome = self
                .env
                .probe(self.probe_start, self.probe_end, self.probe_kind);
            let trip = self.machine_to_program(outcome.trip_position);
            for i in 0..9 {
                let mut v = trip[i];
                if (A..=C).contains(&i) && self.cfg.wrapped_rotary[i - A] {
                    v = v.rem_euclid(360.0);
                }
                self.params[5061 + i] = v;
            }
            self.params[5070] = if outcome.tripped { 1.0 } else { 0.0 };
            self.cur = self.machine_to_program(outcome.final_position);
        }
        if self.toolchange_flag {
            self.toolchange_flag = false;
        }
        let (fault, reason) = self.env.toolchanger_status();
        self.params[5600] = fault;
        self.params[5601] = reason;
        if self.input_flag {
            self.input_flag = false;
            let prev = self.params[5399];
            self.params[5399] = self.env.wait_input(
                self.input_index,
                self.input_digital,
                self.input_mode,
                self.input_timeout,
                prev,
            );
        }
    }

    /// LinuxCNC's `read`: read and parse the next line into `self.block`.
    pub fn read(&mut self) -> R<ReadStatus> {
        self.read_inputs();
        for i in 0..9 {
            self.params[5420 + i] = self.cur[i];
        }
        let abs = self.absolute_position();
        self.params[5021..5030].copy_from_slice(&abs);
        self.fault_word = None;
        self.line_text_override = None;
        let offset = self.tell();
        if !self.read_raw_line()? {
            if let Some(sub) = &self.skipping_to_sub {
                bail!(
                    "EOF in file:{} seeking o-word: o<{}> from line: {}",
                    self.files[self.cur_file].name,
                    sub,
                    self.skipping_start
                );
            }
            if self.percent_flag {
                bail!("File ended with no percent sign");
            }
            bail!("File ended with no percent sign or program end");
        }
        self.sequence_number += 1;
        self.lines_read += 1;
        chk!(self.line_too_long, "Command too long");
        if let Some(limit) = self.cfg.line_limit {
            chk!(
                self.lines_read > limit,
                "Program stopped: it read more than the line limit of {limit} lines"
            );
        }
        self.line_n = block_number_of(&self.raw);
        self.close_and_downcase()?;
        if self.line == b"%" && self.percent_flag {
            self.emit(CanonCmd::Finish);
            if let Some(o) = &self.skipping_o {
                bail!("Failed to find sub 'O{o}' before EOF");
            }
            return Ok(ReadStatus::EndFile);
        }
        self.line_length =
            if self.line.is_empty() || (self.line[0] == b'/' && self.cfg.block_delete) {
                0
            } else {
                self.line.len()
            };
        let mut block = self.take_block();
        block.offset = offset;
        let result = if self.line_length != 0 {
            self.parse_line(&mut block)
        } else {
            block.clear();
            Ok(())
        };
        block.line_number = self.sequence_number;
        self.put_block(block);
        result.map(|_| ReadStatus::Ok)
    }

    /// LinuxCNC's `execute`: run the block just read.
    pub fn execute(&mut self) -> R<ExecStatus> {
        if self.line_length == 0 {
            return Ok(ExecStatus::Ok);
        }
        if self.block.o_type != OType::None || !self.block.o_name.is_empty() {
            return self.convert_control_functions();
        }
        if self.skipping_o.is_some() {
            return Ok(ExecStatus::Ok);
        }
        let numbered = std::mem::take(&mut self.block.assign_numbered);
        for &(n, v) in &numbered {
            self.params[n] = v;
        }
        self.block.assign_numbered = numbered;
        let named = std::mem::take(&mut self.block.assign_named);
        for (name, v) in &named {
            self.store_named_param(name, *v, false)?;
        }
        self.block.assign_named = named;
        if !self.block.remappings.is_empty() {
            return self.execute_remapped_block();
        }
        let mut block = self.take_block();
        let status = self.execute_block(&mut block);
        self.put_block(block);
        status
    }

    /// Take the current block out to work on it beside `self`.
    pub fn take_block(&mut self) -> Box<Block> {
        let spare = self.spare_block.take().unwrap_or_default();
        std::mem::replace(&mut self.block, spare)
    }

    /// Put a block taken with [`Interp::take_block`] back.
    pub fn put_block(&mut self, block: Box<Block>) {
        let spare = std::mem::replace(&mut self.block, block);
        self.spare_block = Some(spare);
    }

    /// Run one line: read it, then execute it.
    pub fn step(&mut self) -> R<Step> {
        match self.read()? {
            ReadStatus::EndFile => return Ok(Step::EndFile),
            ReadStatus::Ok => {}
        }
        match self.execute()? {
            ExecStatus::Exit => Ok(Step::Exit),
            _ => Ok(Step::Continue),
        }
    }

    /// LinuxCNC's `unwind_call`: after an error, leave every subroutine,
    /// restoring #1–#30 and the caller's file position, and forget any
    /// skipping in progress.
    pub fn unwind_call(&mut self) {
        while self.call_level > 0 {
            let level = self.call_level;
            self.contexts[level].named.clear();
            let sub = &mut self.contexts[level - 1];
            sub.sub_name = None;
            let call_type = self.contexts[level].call_type;
            if call_type != CallType::M98Sub {
                for i in 0..SUB_PARAMS {
                    self.params[i + 1] = self.contexts[level - 1].saved_params[i];
                }
            }
            let (file, pos, seq) = {
                let c = &self.contexts[level - 1];
                (c.file, c.position, c.sequence_number)
            };
            let _ = self.seek_to(file, pos);
            self.sequence_number = seq;
            self.call_level -= 1;
        }
        self.sub_name = None;
        self.remap_blocks.clear();
        self.defining_sub = false;
        self.skipping_o = None;
        self.skipping_to_sub = None;
        self.labels.clear();
        self.queue.clear();
        self.queue_endpoint = None;
    }

    /// Save the parameters through the environment (LinuxCNC's `exit`).
    pub fn save_parameters(&mut self) -> Result<(), String> {
        let values = self.params.to_vec();
        self.env.save_parameters(&values)
    }
}

/// What one line did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Step {
    Continue,
    Exit,
    EndFile,
}

/// The spelling of a G-code for messages: `G1`, `G38.2`.
pub(crate) fn gcode_name(code: i32) -> String {
    if code % 10 != 0 {
        format!("G{}.{}", code / 10, code % 10)
    } else {
        format!("G{}", code / 10)
    }
}

/// The N word at the start of a raw line (after blanks and `/`), as
/// LinuxCNC's stand-alone interpreter shows it.
fn block_number_of(raw: &[u8]) -> Option<BlockNumber> {
    let mut k = 0;
    while k < raw.len() && matches!(raw[k], b' ' | b'\t' | b'/') {
        k += 1;
    }
    if k < raw.len() && (raw[k] == b'n' || raw[k] == b'N') {
        let digits = raw[k + 1..]
            .iter()
            .take_while(|c| c.is_ascii_digit())
            .count();
        let mut value: u32 = 0;
        for &d in &raw[k + 1..k + 1 + digits] {
            value = value.saturating_mul(10).saturating_add((d - b'0') as u32);
        }
        Some(BlockNumber {
            value,
            digits: digits.min(255) as u8,
        })
    } else {
        None
    }
}

use crate::error::{bail, chk};

// ----------------------------------------------------------------------
// The public interpreter.

/// An RS274NGC interpreter over one program, yielding [`Canon`] commands.
///
/// It reads the next line only when the consumer asks for more commands,
/// so a program of any length is interpreted in constant memory (O-word
/// loops and subroutines seek back in the file). Errors carry file, line
/// and column. After an error it yields that error and ends, unless
/// [`Config::continue_after_error`] is set.
pub struct Interpreter<'a> {
    st: Interp<'a>,
    /// An error to give once the commands before it have been taken.
    pending_error: Option<InterpError>,
    started: bool,
    done: bool,
    saved: bool,
    exit_status: Option<Ending>,
}

/// How a program ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ending {
    /// M2 or M30.
    ProgramEnd,
    /// The closing `%`.
    Percent,
    /// An error stopped it.
    Error,
}

impl Interpreter<'static> {
    /// Open a program file with the default configuration; `start` is the
    /// machine's current position.
    pub fn open(path: &Path, start: Position) -> std::io::Result<Self> {
        Self::open_with(
            path,
            Config {
                start_position: start,
                ..Config::default()
            },
            Box::new(Offline::default()),
        )
    }

    /// Open a program file with a configuration and an environment.
    pub fn open_with(path: &Path, cfg: Config, env: Box<dyn Environment>) -> std::io::Result<Self> {
        let file = File::open(path)?;
        Ok(Interpreter::with_source(
            Box::new(BufReader::with_capacity(64 * 1024, file)),
            path.display().to_string(),
            Some(path.to_path_buf()),
            cfg,
            env,
        ))
    }

    /// Interpret program text held in memory, naming it `file`.
    pub fn from_text(text: impl Into<String>, file: impl Into<Arc<str>>, start: Position) -> Self {
        Interpreter::new(Cursor::new(text.into().into_bytes()), file, start)
    }
}

impl<'a> Interpreter<'a> {
    /// Interpret a program read from `reader` (which must be seekable, for
    /// O-word loops), naming it `file` in sources and errors.
    pub fn new<Rd: ProgramSource + 'a>(
        reader: Rd,
        file: impl Into<Arc<str>>,
        start: Position,
    ) -> Self {
        Interpreter::with_source(
            Box::new(reader),
            file,
            None,
            Config {
                start_position: start,
                ..Config::default()
            },
            Box::new(Offline::default()),
        )
    }

    /// The most general constructor: a program source, its name, its path
    /// (used to find subroutine files next to it), a configuration and an
    /// environment.
    pub fn with_source(
        reader: Box<dyn ProgramSource + 'a>,
        file: impl Into<Arc<str>>,
        path: Option<PathBuf>,
        cfg: Config,
        env: Box<dyn Environment + 'a>,
    ) -> Self {
        Interpreter {
            st: Interp::new(reader, file.into(), path, cfg, env),
            pending_error: None,
            started: false,
            done: false,
            saved: false,
            exit_status: None,
        }
    }

    /// The tool position after the commands yielded so far were interpreted,
    /// in machine coordinates.
    pub fn position(&self) -> Position {
        self.st.program_to_machine(self.st.cur)
    }

    /// The value of numbered parameter `n` (0 if out of range).
    pub fn parameter(&self, n: usize) -> f64 {
        self.st.params.get(n).copied().unwrap_or(0.0)
    }

    /// G-code lines that set up the modal state the interpreter is in now:
    /// units, plane, distance modes, feed mode, feed rate, spindle speed and
    /// G0/G1 motion mode. Put before the next program text, they carry that
    /// state over as LinuxCNC's MDI keeps it from one line to the next.
    /// Offsets and the coordinate system are not in them: they live in the
    /// parameters (#5161–#5390), which the caller carries over through
    /// [`Config::parameters`]. The units come on a line of their own, since
    /// within one block F is read before G20/G21 applies. A G0 or G1 alone
    /// in a block is a move to where the tool already is, which a caller
    /// may drop.
    pub fn modal_gcode(&self) -> [String; 2] {
        let st = &self.st;
        let units = match st.length_units {
            Units::Inch => "G20",
            Units::Mm => "G21",
        };
        let plane = match st.plane {
            Plane::XY => "G17",
            Plane::XZ => "G18",
            Plane::YZ => "G19",
            Plane::UV => "G17.1",
            Plane::VW => "G19.1",
            Plane::UW => "G18.1",
        };
        let distance = match st.distance_mode {
            Distance::Absolute => "G90",
            Distance::Incremental => "G91",
        };
        let ijk = match st.ijk_distance_mode {
            Distance::Absolute => "G90.1",
            Distance::Incremental => "G91.1",
        };
        let mut second = match st.feed_mode {
            // An inverse-time F holds for one block only: none to carry.
            FeedMode::InverseTime => "G93".to_string(),
            FeedMode::UnitsPerMinute => format!("G94 F{}", st.feed_rate),
            FeedMode::UnitsPerRevolution => format!("G95 F{}", st.feed_rate),
        };
        second.push_str(&format!(" S{}", st.speed));
        // Arcs and cycles need words of their own; only G0 and G1 can stand
        // alone in a block, and G1 only with a feed rate it may use (an
        // inverse-time G1 needs its own F).
        let g1_stands_alone = st.feed_mode != FeedMode::InverseTime && st.feed_rate > 0.0;
        match st.motion_mode {
            g::G0 => second.push_str(" G0"),
            g::G1 if g1_stands_alone => second.push_str(" G1"),
            _ => {}
        }
        [format!("{units} {plane} {distance} {ijk}"), second]
    }

    /// How the program ended, once it has.
    pub fn ending(&self) -> Option<Ending> {
        self.exit_status
    }

    fn finish(&mut self, ending: Ending) {
        self.done = true;
        self.exit_status = Some(ending);
        if !self.saved {
            self.saved = true;
            if let Err(e) = self.st.save_parameters() {
                let source = self.st.source();
                self.st.out.push_back(Canon {
                    source,
                    cmd: CanonCmd::Message(format!("cannot save parameters: {e}")),
                });
            }
        }
    }
}

impl<'a> Iterator for Interpreter<'a> {
    type Item = Result<Canon, InterpError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(c) = self.st.out.pop_front() {
                return Some(Ok(c));
            }
            if let Some(e) = self.pending_error.take() {
                return Some(Err(e));
            }
            if self.done {
                return None;
            }
            if !self.started {
                self.started = true;
                if let Err(f) = self.st.open_program() {
                    let e = self.st.locate(f);
                    self.finish(Ending::Error);
                    return Some(Err(e));
                }
                continue;
            }
            match self.st.step() {
                Ok(Step::Continue) => {}
                Ok(Step::Exit) => self.finish(Ending::ProgramEnd),
                Ok(Step::EndFile) => self.finish(Ending::Percent),
                Err(f) => {
                    let at_eof = f.message.starts_with("File ended with no percent sign")
                        || f.message.starts_with("EOF in file:");
                    // The commands the failing line gave before it failed
                    // come first, as LinuxCNC gives them as it goes.
                    let e = self.st.locate(f);
                    self.st.unwind_call();
                    self.pending_error = Some(e);
                    if !self.st.cfg.continue_after_error || at_eof {
                        self.finish(Ending::Error);
                    }
                }
            }
        }
    }
}

#[allow(unused_imports)]
use crate::canon::Axis as _Axis;
