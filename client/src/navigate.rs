//! Interactive navigation (Funkhouser §3.3.1): the observer moves along its view direction while
//! a mouse button is held and turns towards the mouse cursor.
//!
//! - left button: move forward while turning; right button: move backward while turning;
//!   middle button: spin without moving;
//! - the cursor's distance from the centre of the window sets the turn rate (left/right only,
//!   unless Control is held, which also allows turning up and down); with Control released the
//!   view levels out gradually;
//! - arrow keys spin left, right, up, down one step; keypad 4/6/8/2 move left, right, up,
//!   down and keypad 5 and / move forward and back one step; Escape ends the walk.
//!
//! [`Navigator`] is pure state: the window feeds it [`Controls`] each frame and reads the eye and
//! view direction; [`Recorder`] turns the frames into a replayable [`CameraPath`].

use glam::Vec3;
use portico_data::path::{CameraPath, Keyframe};

/// What the user is doing this frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Controls {
    /// Left button held: move forward while turning.
    pub forward: bool,
    /// Right button held: move backward while turning.
    pub backward: bool,
    /// Middle button held: spin without moving.
    pub spin: bool,
    /// Control held: the cursor may also turn the view up and down.
    pub pitch: bool,
    /// Cursor position in the window, each coordinate -1..1 (x right, y up; 0 = centre).
    pub cursor: [f32; 2],
}

/// One-step key commands (Funkhouser's arrow and keypad keys).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// Left arrow.
    SpinLeft,
    /// Right arrow.
    SpinRight,
    /// Up arrow.
    SpinUp,
    /// Down arrow.
    SpinDown,
    /// Keypad 4.
    Left,
    /// Keypad 6.
    Right,
    /// Keypad 8.
    Up,
    /// Keypad 2.
    Down,
    /// Keypad 5.
    Forward,
    /// Keypad /.
    Back,
}

/// The simulated observer under user control.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Navigator {
    /// Eye position.
    pub eye: Vec3,
    /// Heading, radians about +y (0 looks along +x).
    pub yaw: f32,
    /// Elevation, radians (0 = horizontal).
    pub pitch: f32,
    /// Walking speed with a button held, m/s.
    pub speed: f32,
    /// Turn rate with the cursor at the window's edge, rad/s.
    pub turn: f32,
}

/// Cursor offsets smaller than this (of the half window) do not turn: holding the button with
/// the cursor near the middle walks straight.
const DEAD_ZONE: f32 = 0.1;
/// Steepest view up or down.
const MAX_PITCH: f32 = 1.2;
/// Fraction of the pitch removed per second when Control is released.
const LEVEL_RATE: f32 = 3.0;
/// One key step: metres, and radians.
const STEP_M: f32 = 0.25;
const STEP_RAD: f32 = 0.1;

impl Navigator {
    /// An observer at `eye` looking along the horizontal part of `dir`.
    pub fn new(eye: Vec3, dir: Vec3, speed: f32, turn: f32) -> Navigator {
        Navigator {
            eye,
            yaw: dir.z.atan2(dir.x),
            pitch: 0.0,
            speed,
            turn,
        }
    }

    /// Unit view direction.
    pub fn dir(&self) -> Vec3 {
        Vec3::new(
            self.yaw.cos() * self.pitch.cos(),
            self.pitch.sin(),
            self.yaw.sin() * self.pitch.cos(),
        )
    }

    /// Advances `dt` seconds under `c`; returns the velocity (m/s) for the server's observer.
    pub fn update(&mut self, c: &Controls, dt: f32) -> Vec3 {
        let before = self.eye;
        let held = c.forward || c.backward || c.spin;
        if held {
            let turn = |v: f32| {
                let m = (v.abs() - DEAD_ZONE).max(0.0) / (1.0 - DEAD_ZONE);
                v.signum() * m
            };
            self.yaw += turn(c.cursor[0].clamp(-1.0, 1.0)) * self.turn * dt;
            if c.pitch {
                self.pitch = (self.pitch + turn(c.cursor[1].clamp(-1.0, 1.0)) * self.turn * dt)
                    .clamp(-MAX_PITCH, MAX_PITCH);
            }
            let along = match (c.forward, c.backward) {
                (true, false) => 1.0,
                (false, true) => -1.0,
                _ => 0.0,
            };
            if !c.spin {
                self.eye += self.dir() * along * self.speed * dt;
            }
        }
        if !c.pitch {
            self.pitch *= (1.0 - LEVEL_RATE * dt).max(0.0);
        }
        if dt > 0.0 {
            (self.eye - before) / dt
        } else {
            Vec3::ZERO
        }
    }

    /// Applies one key step.
    pub fn step(&mut self, s: Step) {
        let flat = Vec3::new(self.yaw.cos(), 0.0, self.yaw.sin());
        let right = flat.cross(Vec3::Y);
        match s {
            Step::SpinLeft => self.yaw -= STEP_RAD,
            Step::SpinRight => self.yaw += STEP_RAD,
            Step::SpinUp => self.pitch = (self.pitch + STEP_RAD).min(MAX_PITCH),
            Step::SpinDown => self.pitch = (self.pitch - STEP_RAD).max(-MAX_PITCH),
            Step::Left => self.eye -= right * STEP_M,
            Step::Right => self.eye += right * STEP_M,
            Step::Up => self.eye.y += STEP_M,
            Step::Down => self.eye.y -= STEP_M,
            Step::Forward => self.eye += self.dir() * STEP_M,
            Step::Back => self.eye -= self.dir() * STEP_M,
        }
    }
}

/// Collects an interactive walk as keyframes (`--record`), dropping frames where nothing moved.
#[derive(Debug, Clone, Default)]
pub struct Recorder {
    keyframes: Vec<Keyframe>,
}

impl Recorder {
    /// Notes where the observer was at `t` seconds.
    pub fn note(&mut self, t: f32, eye: Vec3, dir: Vec3) {
        let k = Keyframe {
            t,
            eye: eye.into(),
            dir: dir.into(),
        };
        if let Some(last) = self.keyframes.last()
            && last.eye == k.eye
            && last.dir == k.dir
            && self.keyframes.len() >= 2
            && self.keyframes[self.keyframes.len() - 2].eye == k.eye
            && self.keyframes[self.keyframes.len() - 2].dir == k.dir
        {
            // Standing still: stretch the last keyframe instead of adding one.
            if let Some(l) = self.keyframes.last_mut() {
                l.t = t;
            }
            return;
        }
        self.keyframes.push(k);
    }

    /// The path so far (kind `recorded`).
    pub fn path(&self) -> CameraPath {
        CameraPath {
            kind: "recorded".into(),
            keyframes: self.keyframes.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nav() -> Navigator {
        Navigator::new(Vec3::ZERO, Vec3::X, 2.0, 1.0)
    }

    #[test]
    fn left_button_with_the_cursor_in_the_middle_walks_straight_ahead() {
        let mut n = nav();
        let c = Controls {
            forward: true,
            cursor: [0.05, 0.0],
            ..Controls::default()
        };
        let v = n.update(&c, 0.5);
        assert!(
            (n.eye - Vec3::new(1.0, 0.0, 0.0)).length() < 1e-5,
            "{}",
            n.eye
        );
        assert!((v - Vec3::new(2.0, 0.0, 0.0)).length() < 1e-4);
        assert_eq!(n.yaw, 0.0, "inside the dead zone");
    }

    #[test]
    fn the_cursor_turns_towards_its_side_and_right_button_walks_back() {
        let mut n = nav();
        let c = Controls {
            backward: true,
            cursor: [1.0, 0.0],
            ..Controls::default()
        };
        n.update(&c, 0.1);
        assert!(n.yaw > 0.09, "turned right (towards +z)");
        assert!(n.eye.x < 0.0, "moved backwards");
    }

    #[test]
    fn middle_button_spins_without_moving() {
        let mut n = nav();
        let c = Controls {
            spin: true,
            cursor: [-1.0, 0.0],
            ..Controls::default()
        };
        let v = n.update(&c, 0.5);
        assert_eq!(n.eye, Vec3::ZERO);
        assert_eq!(v, Vec3::ZERO);
        assert!(n.yaw < -0.4);
    }

    #[test]
    fn looking_up_needs_control_and_levels_out_after() {
        let mut n = nav();
        let mut c = Controls {
            spin: true,
            cursor: [0.0, 1.0],
            ..Controls::default()
        };
        n.update(&c, 0.2);
        assert_eq!(n.pitch, 0.0, "no pitch without Control");
        c.pitch = true;
        n.update(&c, 0.2);
        assert!(n.pitch > 0.1);
        let raised = n.pitch;
        c.pitch = false;
        for _ in 0..20 {
            n.update(&c, 0.05);
        }
        assert!(n.pitch.abs() < raised * 0.1, "levelled out: {}", n.pitch);
    }

    #[test]
    fn key_steps_move_and_turn_one_step() {
        let mut n = nav();
        n.step(Step::Forward);
        assert!((n.eye.x - STEP_M).abs() < 1e-6);
        n.step(Step::Up);
        assert!((n.eye.y - STEP_M).abs() < 1e-6);
        n.step(Step::Right);
        assert!(n.eye.z > 0.2, "right of +x is +z");
        n.step(Step::SpinLeft);
        assert!((n.yaw + STEP_RAD).abs() < 1e-6);
    }

    #[test]
    fn a_recorded_walk_replays_as_a_valid_path() {
        let mut n = nav();
        let mut r = Recorder::default();
        let c = Controls {
            forward: true,
            cursor: [0.5, 0.0],
            ..Controls::default()
        };
        for i in 0..10 {
            n.update(&c, 0.05);
            r.note(i as f32 * 0.05, n.eye, n.dir());
        }
        // Standing still for a while adds no keyframes.
        for i in 10..30 {
            r.note(i as f32 * 0.05, n.eye, n.dir());
        }
        let p = r.path();
        assert!(p.validate().is_ok());
        assert_eq!(p.keyframes.len(), 11);
        let (eye, _) = p.sample(0.45);
        assert!((eye - n.eye).length() < 1e-4);
    }
}
