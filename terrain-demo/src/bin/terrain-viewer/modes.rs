//! The viewer's switchable modes: how the terrain's level of detail is chosen (`L`) and what
//! detail is added on top of the coarse-map (`T`). Only what the library has today is listed;
//! a new mode is one more variant here and one more arm where the frame is drawn.

/// How the terrain's level of detail is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LodMode {
    /// terrain-lod's geometry clipmap drawn by terrain-gpu's `ClipmapRenderer`.
    Clipmap,
}

impl LodMode {
    /// Every mode, in the order `L` cycles through them.
    pub const ALL: &[Self] = &[Self::Clipmap];

    /// The mode's name on screen.
    pub fn name(self) -> &'static str {
        match self {
            Self::Clipmap => "clipmap",
        }
    }

    /// The next mode in [`LodMode::ALL`], wrapping.
    pub fn next(self) -> Self {
        cycle(Self::ALL, self)
    }
}

/// What detail is added on top of the coarse-map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DetailMode {
    /// The coarse-map alone.
    None,
}

impl DetailMode {
    /// Every mode, in the order `T` cycles through them.
    pub const ALL: &[Self] = &[Self::None];

    /// The mode's name on screen.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
        }
    }

    /// The next mode in [`DetailMode::ALL`], wrapping.
    pub fn next(self) -> Self {
        cycle(Self::ALL, self)
    }
}

/// The element after `current` in `all`, wrapping (the first when `current` is absent).
fn cycle<T: Copy + PartialEq>(all: &[T], current: T) -> T {
    let i = all.iter().position(|m| *m == current).map_or(0, |i| i + 1);
    all[i % all.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cycling_wraps_and_visits_every_mode() {
        assert_eq!(cycle(&[1, 2, 3], 1), 2);
        assert_eq!(cycle(&[1, 2, 3], 3), 1);
        assert_eq!(cycle(&[1, 2, 3], 9), 1);
        assert_eq!(LodMode::Clipmap.next(), LodMode::Clipmap);
        assert_eq!(DetailMode::None.next().name(), "none");
    }
}
