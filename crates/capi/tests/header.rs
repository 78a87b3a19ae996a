//! The committed C header, `include/edtmap.h`, is what cbindgen makes of
//! `src/lib.rs` now (`EDTMAP_BLESS=1 cargo test -p edtmap-capi --test
//! header` rewrites it after a change to the API).

use std::path::Path;

#[test]
fn committed_header_is_current() {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(crate_dir.join("cbindgen.toml")).expect("cbindgen.toml");
    let bindings = cbindgen::Builder::new()
        .with_crate(crate_dir)
        .with_config(config)
        .generate()
        .expect("cbindgen generates the header");
    let mut generated = Vec::new();
    bindings.write(&mut generated);
    let generated = String::from_utf8(generated).expect("UTF-8");
    let header = crate_dir.join("../../include/edtmap.h");
    if std::env::var("EDTMAP_BLESS").is_ok_and(|v| v == "1") {
        std::fs::write(&header, &generated).expect("write include/edtmap.h");
        return;
    }
    let committed = std::fs::read_to_string(&header).unwrap_or_default();
    assert!(
        committed == generated,
        "include/edtmap.h is out of date with crates/capi/src/lib.rs; regenerate it with EDTMAP_BLESS=1 cargo test -p edtmap-capi --test header"
    );
}
