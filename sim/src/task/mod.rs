//! The task: reward terms, terminations and metrics, and reset-free cycle switching, each a small
//! pure function or state machine over plain values.

pub mod cycles;
pub mod rewards;
pub mod skills;
pub mod terminations;
