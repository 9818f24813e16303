//! The tension ↔ tip-pose dataset (`DESIGN.md` §3).
