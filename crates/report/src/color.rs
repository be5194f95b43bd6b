//! Colours: a plain RGB type for the public API, the series palette and the room tints.

use plotters::style::RGBColor;

/// An sRGB colour, 8 bits per channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Rgb {
    /// Red.
    pub r: u8,
    /// Green.
    pub g: u8,
    /// Blue.
    pub b: u8,
}

impl Rgb {
    /// A colour from its channels.
    pub const fn new(r: u8, g: u8, b: u8) -> Self {
        Self { r, g, b }
    }

    /// A colour from `0xRRGGBB`.
    pub const fn hex(v: u32) -> Self {
        Self::new((v >> 16) as u8, (v >> 8) as u8, v as u8)
    }

    /// The `i`-th colour of [`PALETTE`], wrapping around; series, paths and panels are coloured
    /// with it in order, so the same index gives the same colour in every figure.
    pub fn palette(i: usize) -> Self {
        PALETTE[i % PALETTE.len()]
    }

    pub(crate) fn rgb(self) -> RGBColor {
        RGBColor(self.r, self.g, self.b)
    }
}

/// The series palette: matplotlib's `tab10`, so figures look like the paper's.
pub const PALETTE: [Rgb; 10] = [
    Rgb::hex(0x1f77b4),
    Rgb::hex(0xff7f0e),
    Rgb::hex(0x2ca02c),
    Rgb::hex(0xd62728),
    Rgb::hex(0x9467bd),
    Rgb::hex(0x8c564b),
    Rgb::hex(0xe377c2),
    Rgb::hex(0x7f7f7f),
    Rgb::hex(0xbcbd22),
    Rgb::hex(0x17becf),
];

/// Colours of the floor plan's fixed elements (public so that callers and tests can refer to
/// them).
pub mod plan_colors {
    use super::Rgb;

    /// Picture background (outside the house).
    pub const BACKGROUND: Rgb = Rgb::hex(0xffffff);
    /// Walls.
    pub const WALL: Rgb = Rgb::hex(0x2b2b2b);
    /// The opening of a door, painted over the wall.
    pub const DOOR: Rgb = Rgb::hex(0xe8a33d);
    /// Furniture that is not a container (fill).
    pub const OBSTACLE: Rgb = Rgb::hex(0xcfcfcf);
    /// Outline of furniture that is not a container.
    pub const OBSTACLE_EDGE: Rgb = Rgb::hex(0x9a9a9a);
    /// Containers (fill).
    pub const CONTAINER: Rgb = Rgb::hex(0x8d6e63);
    /// Outline of containers.
    pub const CONTAINER_EDGE: Rgb = Rgb::hex(0x4e342e);
    /// Goal containers in trajectory panels (fill): yellow, unlike any path colour.
    pub const GOAL: Rgb = Rgb::hex(0xffd21f);
    /// Outline of goal containers, and the goal labels.
    pub const GOAL_EDGE: Rgb = Rgb::hex(0x8a6500);
    /// The robot's start marker.
    pub const START: Rgb = Rgb::hex(0x111111);
    /// Where a task brings what it found.
    pub const DESTINATION: Rgb = Rgb::hex(0x1b7f3b);
    /// Text.
    pub const TEXT: Rgb = Rgb::hex(0x222222);
    /// Room names.
    pub const ROOM_TEXT: Rgb = Rgb::hex(0x505050);
    /// Occupied cells of the occupancy overlay (drawn translucent).
    pub const OCCUPIED: Rgb = Rgb::hex(0x3a3a3a);
}

/// Pastel tints for rooms: the common ProcTHOR room types get fixed colours, others a
/// deterministic pick from a spare set, so a plan always colours a type the same way.
pub fn room_tint(room_type: &str) -> Rgb {
    match room_type {
        "Kitchen" => Rgb::hex(0xfbe7b5),
        "LivingRoom" => Rgb::hex(0xd7ecc9),
        "Bedroom" => Rgb::hex(0xd3e2f4),
        "Bathroom" => Rgb::hex(0xe5d8ef),
        other => {
            const SPARE: [Rgb; 6] = [
                Rgb::hex(0xf7d6cc),
                Rgb::hex(0xcdeee9),
                Rgb::hex(0xefe4cf),
                Rgb::hex(0xf3d5e6),
                Rgb::hex(0xe2efc4),
                Rgb::hex(0xe4e4e4),
            ];
            // FNV-1a: stable across runs and platforms, unlike std's hasher.
            let h = other.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
                (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3)
            });
            SPARE[(h % SPARE.len() as u64) as usize]
        }
    }
}
