//! Scripted input (`--script FILE`, `--script-builtin`): input events at given frames, fed
//! through the same [`crate::input::InputState::handle`] as the window's events.
//!
//! One event a line, `FRAME EVENT ARGS`; `#` starts a comment:
//!
//! ```text
//! 0 key w down          # a key down or up (names: w a s d q e space shift f l t plus minus escape)
//! 7 cursor 0.5 0.5      # the cursor to a point of the window, as fractions of its size
//! 8 drag 60 25          # a left-button drag by (dx, dy) pixels from the cursor: a look
//! 12 click left         # a press and release of left or right at the cursor: a stamp
//! 12 press left         # or the press and the release apart
//! 13 release left
//! 20 scroll 2           # wheel steps (flying speed)
//! ```

use crate::input::{Button, InputEvent, Key};
use anyhow::{Context, Result, bail};
use glam::Vec2;

/// The built-in script's text.
pub const BUILTIN: &str = include_str!("builtin_script.txt");

/// One scripted action.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Action {
    Key(Key, bool),
    /// Fractions of the window.
    Cursor(Vec2),
    Drag(Vec2),
    Click(Button),
    Button(Button, bool),
    Scroll(f32),
}

/// A parsed script: actions by frame, in file order within a frame.
#[derive(Debug, Clone, Default)]
pub struct InputScript {
    actions: Vec<(u32, Action)>,
}

fn button(name: &str) -> Result<Button> {
    match name {
        "left" => Ok(Button::Left),
        "right" => Ok(Button::Right),
        _ => bail!("unknown button {name:?} (left or right)"),
    }
}

fn number(s: Option<&str>, what: &str) -> Result<f32> {
    let s = s.with_context(|| format!("missing {what}"))?;
    let v: f32 = s
        .parse()
        .with_context(|| format!("{what} {s:?} is not a number"))?;
    if !v.is_finite() {
        bail!("{what} must be finite");
    }
    Ok(v)
}

impl InputScript {
    /// Parses a script's text; errors name the line.
    pub fn parse(text: &str) -> Result<Self> {
        let mut actions = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let parsed = Self::parse_line(line).with_context(|| format!("script line {}", i + 1));
            actions.push(parsed?);
        }
        // Stable: events of one frame keep their order.
        actions.sort_by_key(|(frame, _)| *frame);
        Ok(Self { actions })
    }

    fn parse_line(line: &str) -> Result<(u32, Action)> {
        let mut words = line.split_whitespace();
        let frame = words.next().context("missing frame")?;
        let frame: u32 = frame
            .parse()
            .with_context(|| format!("frame {frame:?} is not a frame number"))?;
        let event = words.next().context("missing event")?;
        let action = match event {
            "key" => {
                let name = words.next().context("missing key name")?;
                let key = Key::from_name(name).with_context(|| format!("unknown key {name:?}"))?;
                let down = match words.next() {
                    Some("down") => true,
                    Some("up") => false,
                    _ => bail!("a key event ends with down or up"),
                };
                Action::Key(key, down)
            }
            "cursor" => {
                let p = Vec2::new(number(words.next(), "x")?, number(words.next(), "y")?);
                if !(0.0..=1.0).contains(&p.x) || !(0.0..=1.0).contains(&p.y) {
                    bail!("cursor fractions lie in 0..1");
                }
                Action::Cursor(p)
            }
            "drag" => Action::Drag(Vec2::new(
                number(words.next(), "dx")?,
                number(words.next(), "dy")?,
            )),
            "click" => Action::Click(button(words.next().context("missing button")?)?),
            "press" => Action::Button(button(words.next().context("missing button")?)?, true),
            "release" => Action::Button(button(words.next().context("missing button")?)?, false),
            "scroll" => Action::Scroll(number(words.next(), "steps")?),
            other => bail!("unknown event {other:?}"),
        };
        if let Some(extra) = words.next() {
            bail!("unexpected {extra:?} after the event");
        }
        Ok((frame, action))
    }

    /// The input events of `frame` in a window of `size` pixels whose cursor is at `cursor`.
    pub fn events(&self, frame: u32, size: Vec2, mut cursor: Vec2) -> Vec<InputEvent> {
        let mut events = Vec::new();
        for (_, action) in self.actions.iter().filter(|(f, _)| *f == frame) {
            match *action {
                Action::Key(key, pressed) => events.push(InputEvent::Key { key, pressed }),
                Action::Cursor(f) => {
                    cursor = f * size;
                    events.push(InputEvent::Cursor(cursor));
                }
                Action::Drag(d) => {
                    let button = Button::Left;
                    events.push(InputEvent::Button {
                        button,
                        pressed: true,
                    });
                    cursor += d;
                    events.push(InputEvent::Cursor(cursor));
                    events.push(InputEvent::Button {
                        button,
                        pressed: false,
                    });
                }
                Action::Click(button) => {
                    events.push(InputEvent::Button {
                        button,
                        pressed: true,
                    });
                    events.push(InputEvent::Button {
                        button,
                        pressed: false,
                    });
                }
                Action::Button(button, pressed) => {
                    events.push(InputEvent::Button { button, pressed })
                }
                Action::Scroll(s) => events.push(InputEvent::Scroll(s)),
            }
        }
        events
    }

    /// The last frame with an event (0 for an empty script).
    pub fn last_frame(&self) -> u32 {
        self.actions.last().map_or(0, |(f, _)| *f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::{Command, InputState};

    #[test]
    fn the_builtin_script_parses_and_stamps_at_the_centre() {
        let script = InputScript::parse(BUILTIN).unwrap();
        let size = Vec2::new(320.0, 240.0);
        let mut state = InputState::default();
        let mut commands = Vec::new();
        for frame in 0..=script.last_frame() {
            for e in script.events(frame, size, state.cursor()) {
                state.handle(e, &mut commands);
            }
        }
        assert_eq!(
            commands,
            [Command::Stamp {
                button: Button::Left,
                cursor: size * 0.5
            }]
        );
    }

    #[test]
    fn errors_name_the_line() {
        let e = InputScript::parse("0 key w down\n3 jump\n").unwrap_err();
        assert!(format!("{e:#}").contains("line 2"), "{e:#}");
        assert!(InputScript::parse("x key w down").is_err());
        assert!(InputScript::parse("1 key w sideways").is_err());
        assert!(InputScript::parse("1 cursor 2 0").is_err());
        assert!(InputScript::parse("1 click middle").is_err());
    }
}
