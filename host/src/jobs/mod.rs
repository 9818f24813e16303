//! The work a command does, callable from the CLI, the main job and the
//! Python package alike (`docs/design.md` §1): each job takes a typed
//! request and a stop flag, shows progress through the one progress
//! helper, writes its files by the output policy and returns what it did.
//! Jobs sit above the physics, the learners and the run logs they combine,
//! and below the CLI and the pipeline that call them.

pub mod dataset;
pub mod dynamics;
pub mod evaluate;
pub mod fk_batch;
pub mod ik_batch;
pub mod modes;
pub mod step_trace;
pub mod train;
