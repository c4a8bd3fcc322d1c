//! One parsed block (line) of G-code, and the tables of G- and M-codes.
//!
//! G-codes are held as ten times their value (`G38.2` is 382), as LinuxCNC
//! does, so that codes with one decimal place compare exactly.

/// Modal group indices for G-codes (LinuxCNC's numbering).
pub(crate) mod gm {
    pub const MODAL_0: usize = 0;
    pub const MOTION: usize = 1;
    pub const SET_PLANE: usize = 2;
    pub const DISTANCE_MODE: usize = 3;
    pub const IJK_DISTANCE_MODE: usize = 4;
    pub const FEED_MODE: usize = 5;
    pub const LENGTH_UNITS: usize = 6;
    pub const CUTTER_COMP: usize = 7;
    pub const TOOL_LENGTH_OFFSET: usize = 8;
    pub const RETRACT_MODE: usize = 10;
    pub const COORD_SYSTEM: usize = 12;
    pub const CONTROL_MODE: usize = 13;
    pub const SPINDLE_MODE: usize = 14;
    pub const LATHE_DIAMETER_MODE: usize = 15;
    pub const G92_IS_APPLIED: usize = 16;
}

/// G-codes times ten.
#[allow(dead_code)]
pub(crate) mod g {
    pub const G0: i32 = 0;
    pub const G1: i32 = 10;
    pub const G2: i32 = 20;
    pub const G3: i32 = 30;
    pub const G4: i32 = 40;
    pub const G5: i32 = 50;
    pub const G5_1: i32 = 51;
    pub const G5_2: i32 = 52;
    pub const G5_3: i32 = 53;
    pub const G7: i32 = 70;
    pub const G8: i32 = 80;
    pub const G10: i32 = 100;
    pub const G17: i32 = 170;
    pub const G17_1: i32 = 171;
    pub const G18: i32 = 180;
    pub const G18_1: i32 = 181;
    pub const G19: i32 = 190;
    pub const G19_1: i32 = 191;
    pub const G20: i32 = 200;
    pub const G21: i32 = 210;
    pub const G28: i32 = 280;
    pub const G28_1: i32 = 281;
    pub const G30: i32 = 300;
    pub const G30_1: i32 = 301;
    pub const G33: i32 = 330;
    pub const G33_1: i32 = 331;
    pub const G38_2: i32 = 382;
    pub const G38_3: i32 = 383;
    pub const G38_4: i32 = 384;
    pub const G38_5: i32 = 385;
    pub const G40: i32 = 400;
    pub const G41: i32 = 410;
    pub const G41_1: i32 = 411;
    pub const G42: i32 = 420;
    pub const G42_1: i32 = 421;
    pub const G43: i32 = 430;
    pub const G43_1: i32 = 431;
    pub const G43_2: i32 = 432;
    pub const G49: i32 = 490;
    pub const G52: i32 = 520;
    pub const G53: i32 = 530;
    pub const G54: i32 = 540;
    pub const G55: i32 = 550;
    pub const G56: i32 = 560;
    pub const G57: i32 = 570;
    pub const G58: i32 = 580;
    pub const G59: i32 = 590;
    pub const G59_1: i32 = 591;
    pub const G59_2: i32 = 592;
    pub const G59_3: i32 = 593;
    pub const G61: i32 = 610;
    pub const G61_1: i32 = 611;
    pub const G64: i32 = 640;
    pub const G70: i32 = 700;
    pub const G71: i32 = 710;
    pub const G71_1: i32 = 711;
    pub const G71_2: i32 = 712;
    pub const G72: i32 = 720;
    pub const G72_1: i32 = 721;
    pub const G72_2: i32 = 722;
    pub const G73: i32 = 730;
    pub const G74: i32 = 740;
    pub const G76: i32 = 760;
    pub const G80: i32 = 800;
    pub const G81: i32 = 810;
    pub const G82: i32 = 820;
    pub const G83: i32 = 830;
    pub const G84: i32 = 840;
    pub const G85: i32 = 850;
    pub const G86: i32 = 860;
    pub const G87: i32 = 870;
    pub const G88: i32 = 880;
    pub const G89: i32 = 890;
    pub const G90: i32 = 900;
    pub const G90_1: i32 = 901;
    pub const G91: i32 = 910;
    pub const G91_1: i32 = 911;
    pub const G92: i32 = 920;
    pub const G92_1: i32 = 921;
    pub const G92_2: i32 = 922;
    pub const G92_3: i32 = 923;
    pub const G93: i32 = 930;
    pub const G94: i32 = 940;
    pub const G95: i32 = 950;
    pub const G96: i32 = 960;
    pub const G97: i32 = 970;
    pub const G98: i32 = 980;
    pub const G99: i32 = 990;
}

/// The modal group of a G-code (times ten), or `None` if there is no such code.
pub(crate) fn g_group(code: i32) -> Option<usize> {
    use g::*;
    Some(match code {
        G4 | G10 | G28 | G28_1 | G30 | G30_1 | G52 | G53 | G92 | G5_3 => 0,
        G0 | G1 | G2 | G3 | G5 | G5_1 | G5_2 | G33 | G33_1 | G38_2 | G38_3 | G38_4 | G38_5
        | G70 | G71 | G71_1 | G71_2 | G72 | G72_1 | G72_2 | G73 | G74 | G76 | G80 | G81 | G82
        | G83 | G84 | G85 | G86 | G87 | G88 | G89 => 1,
        G17 | G17_1 | G18 | G18_1 | G19 | G19_1 => 2,
        G90 | G91 => 3,
        G90_1 | G91_1 => 4,
        G93 | G94 | G95 => 5,
        G20 | G21 => 6,
        G40 | G41 | G41_1 | G42 | G42_1 => 7,
        G43 | G43_1 | G43_2 | G49 => 8,
        G98 | G99 => 10,
        G54 | G55 | G56 | G57 | G58 | G59 | G59_1 | G59_2 | G59_3 => 12,
        G61 | G61_1 | G64 => 13,
        G96 | G97 => 14,
        G7 | G8 => 15,
        G92_1 | G92_2 | G92_3 => 16,
        _ => return None,
    })
}

/// The modal group of an M-code, or `None` if there is no such code.
pub(crate) fn m_group(code: i32) -> Option<usize> {
    Some(match code {
        0 | 1 | 2 | 30 | 60 | 99 => 4,
        62..=68 => 5,
        6 | 61 => 6,
        3 | 4 | 5 | 19 | 70..=73 => 7,
        7..=9 => 8,
        48..=53 => 9,
        100..=199 => 10,
        _ => return None,
    })
}

/// True for the canned cycles G73, G74 and G81 to G89.
pub(crate) fn is_cycle(motion: i32) -> bool {
    matches!(motion, g::G73 | g::G74) || (g::G81..=g::G89).contains(&motion)
}

/// The kind of an O-word line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum OType {
    None,
    Sub,
    EndSub,
    Call,
    Do,
    While,
    If,
    ElseIf,
    Else,
    EndIf,
    Break,
    Continue,
    EndWhile,
    Return,
    Repeat,
    EndRepeat,
    /// `M98 P…`: Fanuc-style call.
    M98,
    /// `M99` inside a subroutine: Fanuc-style return.
    M99,
    /// A bare `O1234` line: the start of a Fanuc-style subprogram.
    Bare,
}

/// How a subroutine frame was entered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum CallType {
    None,
    NgcSub,
    M98Sub,
    Remap,
}

/// Most subroutine arguments an `O… call` may pass (#1 to #30).
pub(crate) const SUB_PARAMS: usize = 30;

/// Remap execution steps, in LinuxCNC's order of execution. A block that
/// contains remapped codes runs in phases; each step runs once.
pub(crate) mod step {
    pub const COMMENT: u32 = 1;
    pub const SPINDLE_MODE: u32 = 2;
    pub const FEED_MODE: u32 = 3;
    pub const SET_FEED_RATE: u32 = 4;
    pub const SET_SPINDLE_SPEED: u32 = 5;
    pub const PREPARE: u32 = 6;
    pub const M_5: u32 = 7;
    pub const M_6: u32 = 8;
    pub const RETAIN_G43: u32 = 9;
    pub const M_7: u32 = 10;
    pub const M_8: u32 = 11;
    pub const M_9: u32 = 12;
    pub const M_10: u32 = 13;
    pub const DWELL: u32 = 14;
    pub const SET_PLANE: u32 = 15;
    pub const LENGTH_UNITS: u32 = 16;
    pub const LATHE_DIAMETER_MODE: u32 = 17;
    pub const CUTTER_COMP: u32 = 18;
    pub const TOOL_LENGTH_OFFSET: u32 = 19;
    pub const COORD_SYSTEM: u32 = 20;
    pub const CONTROL_MODE: u32 = 21;
    pub const DISTANCE_MODE: u32 = 22;
    pub const IJK_DISTANCE_MODE: u32 = 23;
    pub const RETRACT_MODE: u32 = 24;
    pub const MODAL_0: u32 = 25;
    pub const G92_IS_APPLIED: u32 = 26;
    pub const MOTION: u32 = 27;
    pub const MGROUP4: u32 = 28;
}

/// A parsed block: the words of one line with their values, already
/// evaluated (parameters and expressions are read when the line is read).
#[derive(Clone, Debug)]
pub(crate) struct Block {
    /// Value of each letter word, indexed `letter - 'a'` (G and M excluded).
    pub words: [Option<f64>; 26],
    /// 1-based column of each letter word in the source line.
    pub cols: [u32; 26],
    /// The G-code (×10) given in each modal group, -1 if none.
    pub g_modes: [i32; 17],
    pub g_cols: [u32; 17],
    /// The M-code given in each M modal group, -1 if none.
    pub m_modes: [i32; 11],
    pub m_cols: [u32; 11],
    pub m_count: u32,
    /// An M100–M199 user code is present.
    pub user_m: bool,
    /// The `$` spindle-selection word.
    pub dollar: Option<f64>,
    /// Polar coordinates `@` (radius) and `^` (angle).
    pub radius: Option<f64>,
    pub theta: Option<f64>,
    /// The last `( )` comment of the line (text between the parentheses).
    pub comment: Option<String>,
    /// The N word.
    pub n_number: Option<i64>,
    /// The motion mode this block will execute, after modal inheritance.
    pub motion_to_be: i32,
    pub o_type: OType,
    /// Label of the O-word (`100`, `<name>` lower-cased), qualified for
    /// local labels (`sub#label`).
    pub o_name: String,
    pub o_col: u32,
    /// Arguments of an `O… call`.
    pub params: Vec<f64>,
    pub call_type: CallType,
    /// Numbered and named parameter assignments, applied before execution.
    pub assign_numbered: Vec<(usize, f64)>,
    pub assign_named: Vec<(String, f64)>,
    /// Byte offset of the line in its file (for loops and subroutines).
    pub offset: u64,
    /// 1-based line number.
    pub line_number: u32,
    /// Remapped steps still to run in this block.
    pub remappings: Vec<u32>,
    /// Steps already executed (bit per [`step`] constant).
    pub breadcrumbs: u64,
    /// Index of the remap being executed from this block.
    pub executing_remap: Option<usize>,
    pub phase: u32,
    pub builtin_used: bool,
}

impl Default for Block {
    fn default() -> Self {
        Block {
            words: [None; 26],
            cols: [0; 26],
            g_modes: [-1; 17],
            g_cols: [0; 17],
            m_modes: [-1; 11],
            m_cols: [0; 11],
            m_count: 0,
            user_m: false,
            dollar: None,
            radius: None,
            theta: None,
            comment: None,
            n_number: None,
            motion_to_be: -1,
            o_type: OType::None,
            o_name: String::new(),
            o_col: 0,
            params: Vec::new(),
            call_type: CallType::None,
            assign_numbered: Vec::new(),
            assign_named: Vec::new(),
            offset: 0,
            line_number: 0,
            remappings: Vec::new(),
            breadcrumbs: 0,
            executing_remap: None,
            phase: 0,
            builtin_used: false,
        }
    }
}

impl Block {
    /// Reset to an empty block, keeping allocations.
    pub fn clear(&mut self) {
        self.words = [None; 26];
        self.g_modes = [-1; 17];
        self.m_modes = [-1; 11];
        self.m_count = 0;
        self.user_m = false;
        self.dollar = None;
        self.radius = None;
        self.theta = None;
        self.comment = None;
        self.n_number = None;
        self.motion_to_be = -1;
        self.o_type = OType::None;
        self.o_name.clear();
        self.o_col = 0;
        self.params.clear();
        self.call_type = CallType::None;
        self.assign_numbered.clear();
        self.assign_named.clear();
        self.remappings.clear();
        self.breadcrumbs = 0;
        self.executing_remap = None;
        self.phase = 0;
        self.builtin_used = false;
    }

    /// The value of a letter word.
    #[inline]
    pub fn get(&self, letter: u8) -> Option<f64> {
        self.words[(letter - b'a') as usize]
    }

    /// True if the letter word is present.
    #[inline]
    pub fn has(&self, letter: u8) -> bool {
        self.words[(letter - b'a') as usize].is_some()
    }

    /// The value of a letter word, or `default`.
    #[inline]
    pub fn or(&self, letter: u8, default: f64) -> f64 {
        self.get(letter).unwrap_or(default)
    }

    /// Column of a letter word.
    pub fn col(&self, letter: u8) -> u32 {
        self.cols[(letter - b'a') as usize]
    }

    /// Set a letter word.
    pub fn set(&mut self, letter: u8, value: f64) {
        self.words[(letter - b'a') as usize] = Some(value);
    }

    /// True if any axis word X Y Z A B C U V W is present.
    pub fn any_axis(&self) -> bool {
        b"xyzabcuvw".iter().any(|&l| self.has(l))
    }

    /// P word, or -1 if absent (LinuxCNC's convention for P and Q).
    pub fn p(&self) -> f64 {
        self.or(b'p', -1.0)
    }

    /// Q word, or -1 if absent.
    pub fn q(&self) -> f64 {
        self.or(b'q', -1.0)
    }

    /// L word, or -1 if absent.
    pub fn l(&self) -> i32 {
        self.get(b'l').map(|v| v as i32).unwrap_or(-1)
    }
}

/// LinuxCNC's "nearest integer" for words that must be whole numbers.
pub(crate) fn round_to_int(x: f64) -> i32 {
    (x + 0.5).floor() as i32
}
