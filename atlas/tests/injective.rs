//! `nuvo_atlas::injective::make_injective` on an island of a real bake that fooled its
//! injectivity check (`tests/data/teapot_handle_flap.obj`, see its header).

use std::path::Path;

use nuvo_atlas::injective::{InjectiveOptions, make_injective};
use nuvo_atlas::islands::{IslandPacking, pack_islands};
use nuvo_atlas::load::load_mesh_with_uv;
use nuvo_atlas::uvstats::analyse_uv;

/// Two boundary points of this island have fans that turn more than once round them (by 0.10
/// and 0.17 rad), so 20 faces lie partly over others, although every face is positive and no
/// two boundary segments cross (the crossings are at the points themselves). The check must
/// see it, and the island must come out overlap-free.
#[test]
fn an_island_whose_boundary_fans_turn_more_than_once_is_made_injective() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/teapot_handle_flap.obj");
    let mesh = load_mesh_with_uv(&path).unwrap();
    let before = analyse_uv(&mesh, None, 1024).unwrap().stats;
    assert_eq!((before.flipped_faces, before.overlapping_faces), (0, 20), "the fixture as written");

    let out = make_injective(&mesh, &InjectiveOptions::default()).unwrap();
    let r = &out.report;
    assert_eq!((r.islands_before, r.not_injective_before, r.not_injective_after), (1, 1, 0), "{r:?}");
    // Parts of a split island lie on top of each other until packed.
    let packing = IslandPacking { resolution: 1024, gutter: 2, rotate: true, search: 0 };
    let packed = pack_islands(&out.mesh, &packing).unwrap().mesh;
    let after = analyse_uv(&packed, None, 1024).unwrap().stats;
    assert_eq!((after.flipped_faces, after.overlapping_faces), (0, 0), "{r:?}");
}
