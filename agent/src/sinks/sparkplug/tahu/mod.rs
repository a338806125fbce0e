//! The Sparkplug B payload as Eclipse Tahu defines it: the Rust messages
//! prost generates from the vendored `sparkplug_b.proto` (Tahu's own file,
//! EPL-2.0, its header kept). The generated code is committed
//! (`generated.rs`), so no build needs `protoc`; a test generates it again
//! from the `.proto` (protox, pure Rust, then prost-build) and fails if it
//! differs. Owns the wire types only: which metrics a cell sends, and when,
//! is the sink's (`sinks/sparkplug/book.rs`).
//!
//! To generate it again after changing the `.proto`:
//! `CELLWATCH_REGENERATE=1 cargo test -p cellwatch --lib tahu`.

#[allow(
    missing_docs,
    unreachable_pub,
    clippy::all,
    clippy::pedantic,
    clippy::unwrap_used
)]
mod generated {
    include!("generated.rs");
}

pub(crate) use generated::payload::{metric::Value, Metric, PropertySet, PropertyValue};
pub(crate) use generated::{DataType, Payload};

/// Property values' own oneof.
pub(crate) use generated::payload::property_value::Value as PropertyValueKind;

#[cfg(test)]
mod tests {
    use std::path::Path;

    /// The committed `generated.rs` is exactly what the vendored `.proto`
    /// generates today (or, with `CELLWATCH_REGENERATE=1`, becomes it).
    #[test]
    fn the_committed_code_is_what_the_proto_generates() {
        let here = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/sinks/sparkplug/tahu");
        let files = protox::compile(["sparkplug_b.proto"], [&here]).unwrap();
        let out = tempfile::tempdir().unwrap();
        prost_build::Config::new()
            .out_dir(out.path())
            .compile_fds(files)
            .unwrap();
        let fresh =
            std::fs::read_to_string(out.path().join("org.eclipse.tahu.protobuf.rs")).unwrap();
        let committed = here.join("generated.rs");
        if std::env::var_os("CELLWATCH_REGENERATE").is_some() {
            std::fs::write(&committed, &fresh).unwrap();
        }
        let old = std::fs::read_to_string(&committed).unwrap_or_default();
        assert!(
            old == fresh,
            "{} is not what sparkplug_b.proto generates: run CELLWATCH_REGENERATE=1 cargo test -p cellwatch --lib tahu",
            committed.display()
        );
    }
}
