//! What the person at the page does, turned into [`Controls`] and key steps for the
//! [`Navigator`] (Funkhouser §3.3.1's mouse scheme, plus WASD and touch):
//!
//! - a pointer held on the canvas moves forward (left button, one finger), backward (right
//!   button) or spins (middle button), turning towards the pointer; Control also turns up and
//!   down;
//! - W/S or ↑/↓ walk forward and back, A/D step sideways, Q/E or ←/→ turn, R/F rise and sink
//!   — for as long as the key is held;
//! - T starts or stops the model's standard tour; G switches between walking (the default:
//!   walls stop the observer, floors carry it, stairs lift it: [`portico_client::walk`]) and
//!   flying;
//! - a short click or tap (under 300 ms, barely moving) picks the object under it.

use glam::Vec3;
use portico_client::navigate::{Controls, Navigator};
use std::collections::HashSet;

/// The input state between frames.
#[derive(Debug, Default)]
pub struct Input {
    /// Pointer buttons and position, as the navigator reads them.
    pub controls: Controls,
    /// Keys held now (`KeyboardEvent.code`).
    pub keys: HashSet<String>,
    /// T was pressed since the last frame.
    pub toggle_tour: bool,
    /// Something moved the view since the last frame (stops the tour).
    pub touched: bool,
    /// G was pressed since the last frame.
    pub toggle_gait: bool,
    /// Where (-1..1, y up) a short click or tap asked for a pick since the last frame.
    pub click: Option<[f32; 2]>,
    /// When (ms, the event's clock) and where the pointer went down.
    pressed: Option<(f64, [f32; 2])>,
}

/// A press shorter than this (ms)...
const CLICK_MS: f64 = 300.0;
/// ...that moves less than this (of the canvas's half width) is a click.
const CLICK_MOVE: f32 = 0.03;

impl Input {
    /// A key went down; `true` when the page should not also scroll with it.
    pub fn key_down(&mut self, code: &str) -> bool {
        if code == "KeyT" {
            self.toggle_tour = true;
            return true;
        }
        if code == "KeyG" {
            self.toggle_gait = true;
            return true;
        }
        let ours = matches!(
            code,
            "KeyW"
                | "KeyA"
                | "KeyS"
                | "KeyD"
                | "KeyQ"
                | "KeyE"
                | "KeyR"
                | "KeyF"
                | "ArrowUp"
                | "ArrowDown"
                | "ArrowLeft"
                | "ArrowRight"
        );
        if ours {
            self.keys.insert(code.to_string());
            self.touched = true;
        }
        ours
    }

    /// A key went up.
    pub fn key_up(&mut self, code: &str) {
        self.keys.remove(code);
    }

    /// A pointer button went down at `cursor` (-1..1, y up) at `at_ms`: 0 forward, 1 spin,
    /// 2 backward.
    pub fn pointer_down(&mut self, button: i16, cursor: [f32; 2], ctrl: bool, at_ms: f64) {
        self.pressed = (button == 0).then_some((at_ms, cursor));
        match button {
            0 => self.controls.forward = true,
            1 => self.controls.spin = true,
            2 => self.controls.backward = true,
            _ => return,
        }
        self.controls.cursor = cursor;
        self.controls.pitch = ctrl;
        self.touched = true;
    }

    /// The pointer moved.
    pub fn pointer_move(&mut self, cursor: [f32; 2], ctrl: bool) {
        self.controls.cursor = cursor;
        self.controls.pitch = ctrl;
    }

    /// Every button released (or the pointer left the page) at `at_ms`: a short press that
    /// barely moved is a click.
    pub fn pointer_up(&mut self, at_ms: f64) {
        if let Some((t, at)) = self.pressed.take() {
            let [dx, dy] = [
                self.controls.cursor[0] - at[0],
                self.controls.cursor[1] - at[1],
            ];
            if at_ms - t < CLICK_MS && dx.hypot(dy) < CLICK_MOVE {
                self.click = Some(at);
            }
        }
        self.controls.forward = false;
        self.controls.backward = false;
        self.controls.spin = false;
    }

    /// Moves `nav` by `dt` seconds of what is held at `now_ms` (the events' clock); returns
    /// the velocity (m/s). A left press walks only once it has lasted longer than a click:
    /// a click picks in the view it was made in.
    pub fn apply(&self, nav: &mut Navigator, dt: f32, now_ms: f64) -> Vec3 {
        let before = nav.eye;
        let mut controls = self.controls;
        if self.pressed.is_some_and(|(t, _)| now_ms - t < CLICK_MS) {
            controls.forward = false;
        }
        nav.update(&controls, dt);
        let held = |a: &str, b: &str| self.keys.contains(a) || self.keys.contains(b);
        let axis = |plus: bool, minus: bool| f32::from(u8::from(plus)) - f32::from(u8::from(minus));
        let walk = axis(held("KeyW", "ArrowUp"), held("KeyS", "ArrowDown"));
        let side = axis(self.keys.contains("KeyD"), self.keys.contains("KeyA"));
        let turn = axis(held("KeyE", "ArrowRight"), held("KeyQ", "ArrowLeft"));
        let rise = axis(self.keys.contains("KeyR"), self.keys.contains("KeyF"));
        nav.yaw += turn * nav.turn * 0.5 * dt;
        let flat = Vec3::new(nav.yaw.cos(), 0.0, nav.yaw.sin());
        let right = flat.cross(Vec3::Y);
        nav.eye += (nav.dir() * walk + right * side + Vec3::Y * rise) * nav.speed * dt;
        if dt > 0.0 {
            (nav.eye - before) / dt
        } else {
            Vec3::ZERO
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn held_keys_walk_and_turn() {
        let mut nav = Navigator::new(Vec3::ZERO, Vec3::X, 2.0, 2.0);
        let mut input = Input::default();
        assert!(input.key_down("KeyW"));
        let v = input.apply(&mut nav, 0.5, 0.0);
        assert!(
            (nav.eye - Vec3::new(1.0, 0.0, 0.0)).length() < 1e-5,
            "{}",
            nav.eye
        );
        assert!((v - Vec3::new(2.0, 0.0, 0.0)).length() < 1e-4);
        input.key_up("KeyW");
        assert!(input.key_down("KeyE"));
        input.apply(&mut nav, 0.5, 0.0);
        assert!((nav.yaw - 0.5).abs() < 1e-5, "{}", nav.yaw);
        assert!(
            !input.key_down("KeyZ"),
            "keys that are not ours scroll the page"
        );
    }

    #[test]
    fn a_short_still_press_is_a_click_and_a_held_or_dragged_one_is_not() {
        let mut input = Input::default();
        input.pointer_down(0, [0.2, 0.1], false, 1000.0);
        input.pointer_up(1150.0);
        assert_eq!(input.click.take(), Some([0.2, 0.1]));
        input.pointer_down(0, [0.2, 0.1], false, 1000.0);
        input.pointer_up(1400.0);
        assert_eq!(input.click, None, "held: a walk, not a click");
        input.pointer_down(0, [0.2, 0.1], false, 1000.0);
        input.pointer_move([0.3, 0.1], false);
        input.pointer_up(1100.0);
        assert_eq!(input.click, None, "dragged");
        input.pointer_down(2, [0.2, 0.1], false, 1000.0);
        input.pointer_up(1100.0);
        assert_eq!(input.click, None, "the right button walks back");
        assert!(input.key_down("KeyG") && input.toggle_gait);
    }

    #[test]
    fn a_press_walks_only_once_it_is_longer_than_a_click() {
        let mut nav = Navigator::new(Vec3::ZERO, Vec3::X, 2.0, 2.0);
        let mut input = Input::default();
        input.pointer_down(0, [0.0, 0.0], false, 1000.0);
        input.apply(&mut nav, 0.1, 1100.0);
        assert_eq!(nav.eye, Vec3::ZERO, "still a click");
        input.apply(&mut nav, 0.1, 1400.0);
        assert!(nav.eye.x > 0.0, "held: walking");
    }
}
