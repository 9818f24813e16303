//! The main job: the whole pipeline on the default robot, as far as it is built.

/// Run the pipeline on the default robot, writing under `out/`.
pub fn run_default() -> anyhow::Result<()> {
    Ok(())
}
