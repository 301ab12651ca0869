//! Where the workspace and its target directory are, asked of cargo at run time.
//!
//! A tool built into a shared target directory (`CARGO_TARGET_DIR`) may run from another
//! checkout than the one it was compiled in, so nothing here is baked in at compile time:
//! `cargo metadata` answers for the checkout the tool is run in, and its `target_directory`
//! honours `CARGO_TARGET_DIR` and `.cargo/config.toml`'s `build.target-dir`.

use cargo_metadata::{Metadata, MetadataCommand};
use std::path::{Path, PathBuf};

/// The workspace a tool works on.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Workspace {
    /// The workspace root (the directory of the root `Cargo.toml`).
    pub root: PathBuf,
    /// Cargo's target directory for that workspace, as cargo itself would use it.
    pub target_dir: PathBuf,
}

impl Workspace {
    /// The workspace that contains `dir` (searched upwards for a `Cargo.toml`, as cargo does).
    pub fn containing(dir: &Path) -> Result<Workspace, String> {
        Workspace::query(MetadataCommand::new().current_dir(dir))
    }

    /// The workspace of the current directory (where `cargo xtask ...` was typed).
    pub fn current() -> Result<Workspace, String> {
        let dir = std::env::current_dir().map_err(|e| format!("no current directory: {e}"))?;
        Workspace::containing(&dir)
    }

    /// Runs `cmd` (with `--no-deps`: no resolution, no network) and reads its answer.
    pub fn query(cmd: &mut MetadataCommand) -> Result<Workspace, String> {
        let meta = cmd
            .no_deps()
            .exec()
            .map_err(|e| format!("cannot locate the workspace with `cargo metadata`: {e}"))?;
        Ok(Workspace::from_metadata(&meta))
    }

    /// The paths in `cargo metadata`'s answer.
    pub fn from_metadata(meta: &Metadata) -> Workspace {
        Workspace {
            root: meta.workspace_root.clone().into_std_path_buf(),
            target_dir: meta.target_directory.clone().into_std_path_buf(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn here() -> PathBuf {
        // Test-time only: the crate under test lives in the workspace.
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
    }

    #[test]
    fn the_workspace_root_holds_the_root_manifest_and_the_host_crate() {
        let w = Workspace::containing(&here()).unwrap();
        assert!(w.root.join("Cargo.toml").is_file());
        assert!(here().starts_with(&w.root));
        assert_ne!(
            w.root,
            here(),
            "the root is the workspace's, not the host crate's"
        );
    }

    #[test]
    fn the_target_dir_is_cargo_target_dir_when_set() {
        let dir = std::env::temp_dir().join(format!("morphlink-target-{}", std::process::id()));
        let w = Workspace::query(
            MetadataCommand::new()
                .current_dir(here())
                .env("CARGO_TARGET_DIR", &dir),
        )
        .unwrap();
        assert_eq!(w.target_dir, dir);
        // Without it, cargo's own choice (the default or build.target-dir), never the temp dir.
        let w = Workspace::query(
            MetadataCommand::new()
                .current_dir(here())
                .env_remove("CARGO_TARGET_DIR"),
        )
        .unwrap();
        assert_ne!(w.target_dir, dir);
        assert!(w.target_dir.is_absolute());
    }
}
