//! Where the shared conformance material is: `../shared` beside the
//! repository (CI's layout), or one level further up (a worktree).

use std::path::{Path, PathBuf};

/// `conformance/<corpus>` under the shared directory, if it holds `marker`.
pub fn conformance_dir(corpus: &str, marker: &str) -> Option<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    [root.join("../shared"), root.join("../../shared")]
        .into_iter()
        .map(|p| p.join("conformance").join(corpus))
        .find(|p| p.join(marker).is_file())
}
