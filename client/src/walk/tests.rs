use super::*;
use portico_data::cells::{Cell, Portal};

fn b(min: [f32; 3], max: [f32; 3]) -> Aabb {
    Aabb { min, max }
}

/// Two rooms on the ground floor, 4 × 3 × 4 m, the wall between them 0.2 m thick with a door
/// 1 m wide and 2.1 m high at z 1.5–2.5; an upper room over the first, on a slab 0.2 m thick
/// with a hole at x 1–2, z `hole_z`.
fn building(hole_z: [f32; 2]) -> CellGraph {
    let cells = vec![
        (b([0.0, 0.0, 0.0], [4.0, 3.0, 4.0]), vec![0, 2]), // 0: room A
        (b([4.2, 0.0, 0.0], [8.0, 3.0, 4.0]), vec![1]),    // 1: room B
        (b([4.0, 0.0, 1.5], [4.2, 2.1, 2.5]), vec![0, 1]), // 2: the door's opening
        (b([0.0, 3.2, 0.0], [4.0, 6.2, 4.0]), vec![3]),    // 3: room U above A
        (b([1.0, 3.0, hole_z[0]], [2.0, 3.2, hole_z[1]]), vec![2, 3]), // 4: the hole
    ];
    let portals = vec![
        Portal {
            axis: 0,
            rect: b([4.0, 0.0, 1.5], [4.0, 2.1, 2.5]),
            cells: [0, 2],
        },
        Portal {
            axis: 0,
            rect: b([4.2, 0.0, 1.5], [4.2, 2.1, 2.5]),
            cells: [2, 1],
        },
        Portal {
            axis: 1,
            rect: b([1.0, 3.0, hole_z[0]], [2.0, 3.0, hole_z[1]]),
            cells: [0, 4],
        },
        Portal {
            axis: 1,
            rect: b([1.0, 3.2, hole_z[0]], [2.0, 3.2, hole_z[1]]),
            cells: [4, 3],
        },
    ];
    CellGraph {
        bounds: b([0.0, 0.0, 0.0], [8.0, 6.2, 4.0]),
        cells: cells
            .into_iter()
            .map(|(bounds, portals)| Cell {
                bounds,
                live: true,
                portals,
            })
            .collect(),
        portals,
        tree: Vec::new(),
        grid_fallback: false,
    }
}

/// Walks `frames` frames of 1/60 s at `velocity` (m/s) from `eye`; the eyes it passes.
fn walk(
    w: &mut Walker,
    g: &CellGraph,
    objects: &[Aabb],
    eye: Vec3,
    velocity: Vec3,
    frames: usize,
) -> Vec<Vec3> {
    let dt = 1.0 / 60.0;
    let mut eyes = vec![eye];
    let mut eye = eye;
    for _ in 0..frames {
        w.gather(g, objects, objects.len(), eye);
        eye = w.step(g, eye, velocity * dt, dt);
        eyes.push(eye);
    }
    eyes
}

const E: f32 = EYE_HEIGHT;

#[test]
fn a_wall_stops_the_body_at_its_radius_and_it_slides_along() {
    let g = building([1.0, 2.0]);
    let mut w = Walker::new();
    // Straight at the wall between the rooms, away from the door.
    let eyes = walk(&mut w, &g, &[], Vec3::new(2.0, E, 0.6), Vec3::X * 1.5, 180);
    let last = *eyes.last().unwrap();
    assert!((last.x - 3.75).abs() < 0.02, "stopped at {last}");
    assert!(
        (last.y - E).abs() < 1e-4 && (last.z - 0.6).abs() < 1e-4,
        "{last}"
    );
    // At an angle into the wall between rooms, away from the door: stopped in x, on in z.
    let eyes = walk(
        &mut w,
        &g,
        &[],
        Vec3::new(3.5, E, 3.5),
        Vec3::new(1.0, 0.0, -0.3),
        60,
    );
    let last = *eyes.last().unwrap();
    assert!(
        last.x <= 3.75 + 1e-3 && last.z < 3.3,
        "did not slide: {last}"
    );
    // Fly mode is the caller's: nothing here moves past a wall on its own.
    assert!(eyes.iter().all(|e| e.x <= 3.76), "{eyes:?}");
}

#[test]
fn a_door_lets_the_body_through_and_its_frame_does_not() {
    let g = building([1.0, 2.0]);
    let mut w = Walker::new();
    let eyes = walk(&mut w, &g, &[], Vec3::new(2.0, E, 2.0), Vec3::X * 1.5, 240);
    let last = *eyes.last().unwrap();
    assert!(last.x > 6.0, "the door stopped the body: {last}");
    assert!(
        eyes.iter().all(|e| (e.y - E).abs() < 1e-4),
        "the floor is level"
    );
    // Through the door's edge: the body's side meets the frame.
    let eyes = walk(&mut w, &g, &[], Vec3::new(2.0, E, 1.6), Vec3::X * 1.5, 240);
    assert!(
        eyes.last().unwrap().x < 4.0,
        "passed through the door frame: {:?}",
        eyes.last()
    );
}

#[test]
fn walking_over_a_hole_drops_the_body_to_the_floor_below() {
    let g = building([1.0, 2.0]);
    let mut w = Walker::new();
    let start = Vec3::new(3.5, 3.2 + E, 1.5);
    let eyes = walk(&mut w, &g, &[], start, -Vec3::X * 1.5, 120);
    // Level on the upper floor until the hole, then falling, then on the floor below.
    let over = eyes
        .iter()
        .position(|e| e.x < 2.0)
        .expect("reached the hole");
    assert!(
        eyes[..over].iter().all(|e| (e.y - start.y).abs() < 1e-4),
        "{eyes:?}"
    );
    let last = *eyes.last().unwrap();
    assert!((last.y - E).abs() < 1e-4, "landed at {last}");
    // A fall takes the time gravity takes: 3.2 m in √(2h/g), at 60 frames a second.
    let falling = eyes.windows(2).filter(|p| p[1].y < p[0].y - 1e-6).count() as f32;
    let expected = (2.0 * 3.2 / GRAVITY).sqrt() * 60.0;
    assert!(
        (falling - expected).abs() <= 2.0,
        "fell for {falling} frames, not {expected}"
    );
    assert!(!w.falling());
}

#[test]
fn low_objects_are_stepped_onto_and_tall_ones_stop_the_body() {
    let g = building([1.0, 2.0]);
    let platform = b([2.5, 0.0, 0.0], [3.0, 0.2, 4.0]);
    let desk = b([2.5, 0.0, 0.0], [3.0, 0.75, 4.0]);
    let mut w = Walker::new();
    let eyes = walk(
        &mut w,
        &g,
        &[platform],
        Vec3::new(1.0, E, 3.0),
        Vec3::X * 1.5,
        120,
    );
    let top = eyes.iter().map(|e| e.y).fold(0.0, f32::max);
    assert!((top - (0.2 + E)).abs() < 1e-4, "not stepped onto: {top}");
    assert!(
        (eyes.last().unwrap().y - E).abs() < 1e-4,
        "not stepped down"
    );
    let mut w = Walker::new();
    let eyes = walk(
        &mut w,
        &g,
        &[desk],
        Vec3::new(1.0, E, 3.0),
        Vec3::X * 1.5,
        60,
    );
    let last = *eyes.last().unwrap();
    assert!(
        (last.x - 2.25).abs() < 0.02 && (last.y - E).abs() < 1e-4,
        "{last}"
    );
}

#[test]
fn a_flight_of_stairs_is_climbed_to_the_floor_above_and_its_side_is_a_wall() {
    // The hole runs over the flight, which climbs +z from room A's floor to room U's.
    let g = building([0.5, 3.5]);
    let flight = b([1.0, 0.0, 0.5], [2.0, 3.2, 3.5]);
    let mut w = Walker::new();
    let eyes = walk(
        &mut w,
        &g,
        &[flight],
        Vec3::new(1.5, E, 0.2),
        Vec3::Z * 1.5,
        240,
    );
    let last = *eyes.last().unwrap();
    assert!(
        (last.y - (3.2 + E)).abs() < 1e-3 && last.z > 3.6,
        "not up the stairs: {last}"
    );
    // Climbed, not lifted: up the ramp a little each frame, nothing more than a step at once
    // (the last tread to the landing), and most frames rising.
    let rises: Vec<f32> = eyes.windows(2).map(|p| p[1].y - p[0].y).collect();
    let steepest = rises.iter().copied().fold(0.0, f32::max);
    assert!(steepest <= Body::default().step + 1e-4, "{steepest}");
    let climbing = rises.iter().filter(|&&r| r > 0.0).count();
    assert!(climbing > 60, "rose in {climbing} frames");
    // And down again.
    let eyes = walk(&mut w, &g, &[flight], last, -Vec3::Z * 1.5, 240);
    assert!(
        (eyes.last().unwrap().y - E).abs() < 1e-3,
        "{:?}",
        eyes.last()
    );
    // Into its side from the floor: it is a wall where it stands above a step.
    let mut w = Walker::new();
    let eyes = walk(
        &mut w,
        &g,
        &[flight],
        Vec3::new(3.5, E, 1.2),
        -Vec3::X * 1.5,
        120,
    );
    let last = *eyes.last().unwrap();
    assert!(
        last.x > 2.2 && (last.y - E).abs() < 1e-4,
        "walked into the flight's side: {last}"
    );
    // Over the hole from the floor above: down onto the flight.
    let mut w = Walker::new();
    let eyes = walk(
        &mut w,
        &g,
        &[flight],
        Vec3::new(3.5, 3.2 + E, 2.0),
        -Vec3::X * 1.5,
        120,
    );
    let last = *eyes.last().unwrap();
    assert!(
        last.y < 3.2 + E - 0.5 && last.y > E,
        "not lowered onto the flight: {last}"
    );
}

#[test]
fn a_desk_is_not_a_flight() {
    let g = building([1.0, 2.0]);
    let body = Body::default();
    assert!(flight(&g, None, &body, &b([2.5, 0.0, 0.5], [3.0, 0.75, 2.0])).is_none());
    let wardrobe = b([1.0, 0.0, 0.5], [2.0, 2.5, 3.5]);
    assert!(
        flight(&g, None, &body, &wardrobe).is_none(),
        "no floor at its head: a tall box"
    );
    let g = building([0.5, 3.5]);
    let up = flight(&g, None, &body, &b([1.0, 0.0, 0.5], [2.0, 3.2, 3.5])).expect("a flight");
    assert!(up.rises && up.axis == 2);
}

#[test]
fn outside_every_cell_the_walker_holds_nothing_back() {
    let g = building([1.0, 2.0]);
    let mut w = Walker::new();
    let eyes = walk(
        &mut w,
        &g,
        &[],
        Vec3::new(-5.0, 10.0, -5.0),
        Vec3::X * 1.5,
        30,
    );
    let last = *eyes.last().unwrap();
    assert!(
        (last - Vec3::new(-5.0 + 0.75, 10.0, -5.0)).length() < 1e-3,
        "{last}"
    );
}

#[test]
fn a_body_put_against_a_wall_walks_away_from_it() {
    // Closer to the wall than its radius (a jump, or a start by a wall): a side probe would
    // start in the next room, beyond the 0.2 m wall; it is not the body's, and does not hold it.
    let g = building([1.0, 2.0]);
    let mut w = Walker::new();
    let eyes = walk(&mut w, &g, &[], Vec3::new(3.98, E, 0.6), -Vec3::X * 1.5, 60);
    assert!(
        eyes.last().unwrap().x < 2.6,
        "held by the wall: {:?}",
        eyes.last()
    );
    let eyes = walk(&mut w, &g, &[], Vec3::new(3.98, E, 0.6), Vec3::Z * 1.5, 30);
    assert!(
        eyes.last().unwrap().z > 1.2,
        "held along the wall: {:?}",
        eyes.last()
    );
}
