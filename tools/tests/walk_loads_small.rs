//! The walk-loads accounting on the tiny city: what a walk loaded splits exactly into first loads
//! and refinements, the floor lies under it, naive loads no internal level, and η = 0 loads what
//! naive loads.

use hdov::city::WalkKind;
use hdov::{Database, Mode, QueryParams, SessionParams};
use hdov_tools::walk_loads::walk;

#[test]
fn a_walks_loads_split_into_first_loads_and_refinements_above_the_floor() {
    let dir = tempfile::tempdir().unwrap();
    let (_, db_dir) = hdov_testkit::scenes::tiny_city_database(dir.path());
    let db = Database::open(&db_dir).unwrap();
    let session = |query| SessionParams { query, ..Default::default() };
    for kind in WalkKind::ALL {
        let path = hdov::city::walk(db.grid().unwrap(), kind, 40);
        let naive =
            walk(&db, &path, &session(QueryParams { mode: Mode::Naive, eta: 0.0, ..Default::default() })).unwrap();
        let eta0 = walk(&db, &path, &session(QueryParams { eta: 0.0, ..Default::default() })).unwrap();
        let default = walk(&db, &path, &session(QueryParams::default())).unwrap();
        assert!(naive.loaded > 0, "{}: the walk loads something", kind.name());
        assert_eq!(naive.first[1] + naive.refine[1] + naive.floor[1], 0, "naive draws no internal level");
        assert_eq!(eta0, naive, "{}: η = 0 is the naive answer, load for load", kind.name());
        for l in [naive, default] {
            let [first, refine, floor] = [l.first, l.refine, l.floor].map(|s| s[0] + s[1]);
            assert_eq!(first + refine, l.loaded, "{}: every loaded byte is a first load or a refinement", kind.name());
            assert!(first <= floor && floor <= l.loaded, "{}: {l:?}", kind.name());
        }
    }
}
