// cellwatch's patch: the crate as published also validates its example
// `config.json5` against the configuration's JSON schema here (build
// dependencies jsonschema and schemars); only what the code needs is kept.
fn main() {
    // Add rustc version to zenohd
    let version_meta = rustc_version::version_meta().unwrap();
    println!(
        "cargo:rustc-env=RUSTC_VERSION={}",
        version_meta.short_version_string
    );
}
