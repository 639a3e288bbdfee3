//! Input, as one stream of [`InputEvent`]s whatever their source: the window's events are
//! translated into them, and the scripted input of `--script` is a list of them. Both go
//! through [`InputState::handle`], which keeps what is held and turns presses and clicks into
//! [`Command`]s for the frame.

use crate::fly_camera::Motion;
use glam::Vec2;
use std::collections::HashSet;
use winit::keyboard::KeyCode;

/// A button press that moves the cursor further than this (pixels) is a drag, not a click.
const DRAG_THRESHOLD: f32 = 4.0;

/// The keys the viewer uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Key {
    W,
    A,
    S,
    D,
    Q,
    E,
    Space,
    Shift,
    F,
    L,
    T,
    Plus,
    Minus,
    Escape,
}

impl Key {
    /// Every key with its name in scripts.
    const NAMES: &[(Key, &str)] = &[
        (Key::W, "w"),
        (Key::A, "a"),
        (Key::S, "s"),
        (Key::D, "d"),
        (Key::Q, "q"),
        (Key::E, "e"),
        (Key::Space, "space"),
        (Key::Shift, "shift"),
        (Key::F, "f"),
        (Key::L, "l"),
        (Key::T, "t"),
        (Key::Plus, "plus"),
        (Key::Minus, "minus"),
        (Key::Escape, "escape"),
    ];

    /// The key a script names (`w`, `space`, `plus`, ...), case-insensitive.
    pub fn from_name(name: &str) -> Option<Key> {
        let name = name.to_ascii_lowercase();
        Self::NAMES
            .iter()
            .find(|(_, n)| *n == name)
            .map(|(k, _)| *k)
    }

    /// The key of a physical key code of the window (US layout positions).
    pub fn from_code(code: KeyCode) -> Option<Key> {
        Some(match code {
            KeyCode::KeyW | KeyCode::ArrowUp => Key::W,
            KeyCode::KeyA | KeyCode::ArrowLeft => Key::A,
            KeyCode::KeyS | KeyCode::ArrowDown => Key::S,
            KeyCode::KeyD | KeyCode::ArrowRight => Key::D,
            KeyCode::KeyQ => Key::Q,
            KeyCode::KeyE => Key::E,
            KeyCode::Space => Key::Space,
            KeyCode::ShiftLeft | KeyCode::ShiftRight => Key::Shift,
            KeyCode::KeyF => Key::F,
            KeyCode::KeyL => Key::L,
            KeyCode::KeyT => Key::T,
            KeyCode::Equal | KeyCode::NumpadAdd => Key::Plus,
            KeyCode::Minus | KeyCode::NumpadSubtract => Key::Minus,
            KeyCode::Escape => Key::Escape,
            _ => return None,
        })
    }
}

/// A mouse button the viewer uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Button {
    /// Click: a crater. Drag: look.
    Left,
    /// Click: a footprint. Drag: look.
    Right,
}

/// One input event, from the window or a script.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InputEvent {
    /// A key went down or up.
    Key { key: Key, pressed: bool },
    /// The cursor moved to this position (window pixels from the top left).
    Cursor(Vec2),
    /// A mouse button went down or up (at the cursor).
    Button { button: Button, pressed: bool },
    /// The wheel turned by this many steps (up is positive).
    Scroll(f32),
}

/// What the app does because of input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Stamp at the terrain under this cursor position: a crater (left) or a footprint (right).
    Stamp {
        button: Button,
        cursor: Vec2,
    },
    ToggleWireframe,
    CycleLod,
    CycleDetail,
    /// One clipmap level more (+1) or fewer (-1).
    Levels(i32),
    Quit,
}

/// A press of a button not yet released: where it started and whether it has become a drag.
#[derive(Debug, Clone, Copy)]
struct Press {
    button: Button,
    start: Vec2,
    dragged: bool,
}

/// What input holds between events: keys down, the cursor, a press in progress, and the look
/// and scroll not yet applied to the camera.
#[derive(Debug, Default)]
pub struct InputState {
    held: HashSet<Key>,
    cursor: Vec2,
    press: Option<Press>,
    look: Vec2,
    scroll: f32,
}

impl InputState {
    /// Applies `event`, appending the commands it causes to `commands`.
    pub fn handle(&mut self, event: InputEvent, commands: &mut Vec<Command>) {
        match event {
            InputEvent::Key { key, pressed: true } => {
                // Auto-repeat sends presses of a held key: those toggle nothing.
                if self.held.insert(key) {
                    let command = match key {
                        Key::F => Some(Command::ToggleWireframe),
                        Key::L => Some(Command::CycleLod),
                        Key::T => Some(Command::CycleDetail),
                        Key::Plus => Some(Command::Levels(1)),
                        Key::Minus => Some(Command::Levels(-1)),
                        Key::Escape => Some(Command::Quit),
                        _ => None,
                    };
                    commands.extend(command);
                }
            }
            InputEvent::Key {
                key,
                pressed: false,
            } => {
                self.held.remove(&key);
            }
            InputEvent::Cursor(pos) => {
                if let Some(press) = self.press.as_mut() {
                    if (pos - press.start).length() > DRAG_THRESHOLD {
                        press.dragged = true;
                    }
                    self.look += pos - self.cursor;
                }
                self.cursor = pos;
            }
            InputEvent::Button {
                button,
                pressed: true,
            } => {
                self.press = Some(Press {
                    button,
                    start: self.cursor,
                    dragged: false,
                });
            }
            InputEvent::Button {
                button,
                pressed: false,
            } => {
                if let Some(press) = self.press.take()
                    && press.button == button
                    && !press.dragged
                {
                    commands.push(Command::Stamp {
                        button,
                        cursor: self.cursor,
                    });
                }
            }
            InputEvent::Scroll(steps) => self.scroll += steps,
        }
    }

    /// The movement keys held.
    pub fn motion(&self) -> Motion {
        let held = |k| self.held.contains(&k);
        Motion {
            forward: held(Key::W),
            back: held(Key::S),
            left: held(Key::A),
            right: held(Key::D),
            up: held(Key::Space) || held(Key::E),
            down: held(Key::Shift) || held(Key::Q),
        }
    }

    /// The drag (pixels) since the last call.
    pub fn take_look(&mut self) -> Vec2 {
        std::mem::take(&mut self.look)
    }

    /// The scroll steps since the last call.
    pub fn take_scroll(&mut self) -> f32 {
        std::mem::take(&mut self.scroll)
    }

    /// The cursor position (window pixels).
    pub fn cursor(&self) -> Vec2 {
        self.cursor
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(events: &[InputEvent]) -> (InputState, Vec<Command>) {
        let mut state = InputState::default();
        let mut commands = Vec::new();
        for e in events {
            state.handle(*e, &mut commands);
        }
        (state, commands)
    }

    #[test]
    fn a_click_stamps_and_a_drag_looks() {
        let at = Vec2::new(50.0, 40.0);
        let (_, commands) = run(&[
            InputEvent::Cursor(at),
            InputEvent::Button {
                button: Button::Left,
                pressed: true,
            },
            InputEvent::Button {
                button: Button::Left,
                pressed: false,
            },
        ]);
        assert_eq!(
            commands,
            [Command::Stamp {
                button: Button::Left,
                cursor: at
            }]
        );
        let (mut state, commands) = run(&[
            InputEvent::Cursor(at),
            InputEvent::Button {
                button: Button::Right,
                pressed: true,
            },
            InputEvent::Cursor(at + Vec2::new(30.0, -10.0)),
            InputEvent::Button {
                button: Button::Right,
                pressed: false,
            },
        ]);
        assert!(commands.is_empty());
        assert_eq!(state.take_look(), Vec2::new(30.0, -10.0));
        assert_eq!(state.take_look(), Vec2::ZERO);
    }

    #[test]
    fn held_keys_move_and_repeats_toggle_once() {
        let f = InputEvent::Key {
            key: Key::F,
            pressed: true,
        };
        let (state, commands) = run(&[
            f,
            f,
            InputEvent::Key {
                key: Key::W,
                pressed: true,
            },
            InputEvent::Key {
                key: Key::Shift,
                pressed: true,
            },
        ]);
        assert_eq!(commands, [Command::ToggleWireframe]);
        let m = state.motion();
        assert!(m.forward && m.down && !m.back);
        assert_eq!(Key::from_name("SPACE"), Some(Key::Space));
        assert_eq!(Key::from_code(KeyCode::Equal), Some(Key::Plus));
    }
}
