//! Creases of real meshes (`uvstats::creased_faces`), against counts computed independently in
//! NumPy from the OBJ files (faces with an edge neighbour whose normal is more than 90° away).

use nuvo_atlas::uvstats::creased_faces;
use nuvo_geometry::load::load_mesh;
use nuvo_geometry::testdata::data_file;

fn creased(rel: &str) -> usize {
    let mesh = load_mesh(&data_file(rel)).expect("the test mesh loads");
    creased_faces(&mesh).iter().filter(|&&c| c).count()
}

#[test]
fn the_stanford_bunny_folds_back_on_itself_at_36_faces() {
    // The scan has a few tiny folded triangles; Nuvo's 3-D field flips some of them in every run.
    assert_eq!(creased("meshes/stanford-bunny.obj"), 36);
}

#[test]
fn spot_has_no_creases() {
    assert_eq!(creased("meshes/spot.obj"), 0);
}
