//! The backend conformance suite (`edtmap_conformance`) on the CPU,
//! through the `Backend` trait, plus the batch EDT in every scan layout:
//! all must give the same integer results.

use edtmap_conformance::check_batch_edt;
use edtmap_cpu::edt::ScanLayout;
use edtmap_cpu::CpuBackend;

edtmap_conformance::conformance_tests!(Some(CpuBackend::default()));

#[test]
fn batch_edt_matches_the_separable_oracle_in_every_layout() {
    let layouts = [
        ScanLayout::PerLine,
        ScanLayout::TiledEnvelope { lanes: 5 },
        ScanLayout::Tiled { lanes: 3 },
        ScanLayout::Tiled { lanes: 16 },
        ScanLayout::default(),
    ];
    for layout in layouts {
        let mut backend = CpuBackend::with_layout(layout);
        let checked = check_batch_edt(&mut backend).unwrap_or_else(|e| panic!("{layout:?}: {e}"));
        assert!(checked > 100_000);
    }
}
