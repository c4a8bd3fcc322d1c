//! Lathe roughing and finishing cycles G70, G71 and G72.

use crate::block::Block;
use crate::error::{bail, R};
use crate::interp::Interp;

impl Interp<'_> {
    /// G70–G72.
    pub(crate) fn convert_g7x(&mut self, motion: i32, _b: &mut Block) -> R {
        bail!(
            "{}: lathe cycles G70, G71 and G72 are not supported yet",
            crate::interp::gcode_name(motion)
        )
    }

    /// G76 threading.
    pub(crate) fn convert_threading_cycle(&mut self, _b: &Block, _end: [f64; 9]) -> R {
        bail!("G76: threading cycles are not supported yet")
    }
}
