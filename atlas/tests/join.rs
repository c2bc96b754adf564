//! `nuvo_atlas::join::join_small_islands` on real atlases, run by hand: joins the small islands
//! of the atlases named in `$NUVO_JOIN_OBJ` (paths separated by `:`, e.g. suite runs re-baked
//! without the join) and prints what it did and how long it took, checking that, once the
//! islands are packed again (joined faces may reach into another island's place until then),
//! it adds no flipped or overlapping face (on the 1024² UV raster).
//! `NUVO_JOIN_OBJ=a.obj:b.obj cargo test -p nuvo-atlas --release --test join -- --ignored --nocapture`.

use nuvo_atlas::islands::{IslandPacking, pack_islands};
use nuvo_atlas::join::{JoinOptions, join_small_islands};
use nuvo_atlas::load::load_mesh_with_uv;
use nuvo_atlas::uvstats::analyse_uv;

#[test]
#[ignore = "needs atlases named in $NUVO_JOIN_OBJ; prints numbers"]
fn join_by_hand() {
    let paths = std::env::var("NUVO_JOIN_OBJ").expect("NUVO_JOIN_OBJ");
    for path in paths.split(':') {
        let m = load_mesh_with_uv(std::path::Path::new(path)).expect("an OBJ with UVs");
        let t = std::time::Instant::now();
        let out = join_small_islands(&m, &JoinOptions::default()).unwrap();
        let dt = t.elapsed();
        let packing = IslandPacking { resolution: 2048, gutter: 4, rotate: true, search: 0 };
        let packed = pack_islands(&out.mesh, &packing).unwrap().mesh;
        let (before, after) =
            (analyse_uv(&m, None, 1024).unwrap().stats, analyse_uv(&packed, None, 1024).unwrap().stats);
        println!(
            "{path}: {:?}, {:.0} ms; charts {} -> {}, flipped {} -> {}, overlapping {} -> {}",
            out.report,
            dt.as_secs_f64() * 1e3,
            before.charts,
            after.charts,
            before.flipped_faces,
            after.flipped_faces,
            before.overlapping_faces,
            after.overlapping_faces
        );
        assert!(
            after.flipped_faces <= before.flipped_faces
                && after.overlapping_faces <= before.overlapping_faces
        );
    }
}
