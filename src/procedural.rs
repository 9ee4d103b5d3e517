//! Procedural scenes (placeholder until the generator lands).
