//! Walk mode on the cooked demo level (`make cook` writes build/temple.pack before `make test`
//! runs this; without it the test says so and passes): from the player spawn round the fountain,
//! up the portico step and through the main door into the hall.

use engine::scene::walk::{WalkMesh, BODY_RADIUS_M};
use glam::Vec3;
use std::path::Path;

/// Walk `legs` of (direction, metres) in 10 cm steps from `from`; where the feet end.
fn walk(m: &WalkMesh, from: Vec3, legs: &[(Vec3, f32)]) -> Vec3 {
    let mut p = from;
    for &(dir, metres) in legs {
        for _ in 0..(metres / 0.1).round() as usize {
            p = m.step(p, dir * 0.1);
        }
    }
    p
}

#[test]
fn the_player_walks_round_the_fountain_up_the_steps_and_into_the_hall() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../build/temple.pack");
    if !path.exists() {
        eprintln!("skipped: {} not found (`make cook` makes it)", path.display());
        return;
    }
    let pack = pack::Pack::read_file(&path).unwrap();
    let m = WalkMesh::from_pack(&pack);
    // content/levels/temple.toml: the player spawn at (0, 0, 18); the fountain's basin, radius
    // 2.4 at z 10; the portico step (top 0.3) at z 4.0..5.2 and the portico floor (top 0.6)
    // at z -0.4..4.4; the main door 3.2 m wide in the front wall at z -0.4..0; the hall's floor
    // (top 0.6) behind it.
    let spawn = Vec3::new(0.0, 0.0, 18.0);
    let at_basin = walk(&m, spawn, &[(Vec3::NEG_Z, 8.0)]);
    assert!((at_basin.z - (12.4 + BODY_RADIUS_M)).abs() < 0.15 && at_basin.y == 0.0, "the basin did not stop the walk: {at_basin}");
    let on_step = walk(&m, spawn, &[(Vec3::X, 5.0), (Vec3::NEG_Z, 12.0), (Vec3::NEG_X, 5.0), (Vec3::NEG_Z, 1.4)]);
    assert!((on_step - Vec3::new(0.0, 0.3, 4.6)).length() < 1e-3, "not on the portico step: {on_step}");
    let in_hall = walk(&m, on_step, &[(Vec3::NEG_Z, 7.6)]);
    assert!((in_hall - Vec3::new(0.0, 0.6, -3.0)).length() < 1e-3, "not in the hall: {in_hall}");
    // The front wall beside the door stops the body.
    let at_wall = walk(&m, on_step + Vec3::new(4.0, 0.0, 0.0), &[(Vec3::NEG_Z, 7.6)]);
    assert!(at_wall.z > 0.0 && at_wall.y == 0.6, "walked through the front wall: {at_wall}");
}
