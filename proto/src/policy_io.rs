//! A policy's input and output contract, as its model declares it: the one description that
//! collection, the agent, replay and the Python package all read.
//!
//! A policy sees one robot and nothing else: its own scan, its own compass heading and the goal
//! every robot is given. From that it is fed an occupancy image of the scan and a
//! short vector of scalars beside it ([`AuxLayout`], in the order the model declares in its
//! `formation.aux` metadata; the paper's `(delta_phi, d*)` where it declares none), and it answers
//! what its `formation.output` declares ([`PolicyOutput`]). [`PolicyIo`] holds all of it.
//!
//! A model may also take its scan's ranges as floats ([`RangeInput`], declared in its
//! `formation.ranges` metadata): the image resolves a neighbour to one cell (10 cm at the
//! shipped window), the ranges to about a centimetre, which is the precision the strict check's
//! small edge errors need (issue 34).
//!
//! A model may take the neighbours its robot detects in its scan ([`NeighbourInput`], declared
//! in `formation.neighbours`): each one's centre to a few millimetres and whether the robot holds
//! it at d*, the per-pair structure the expert's own law has (issue 34).
//!
//! **Adding a scalar input** is a variant of [`AuxInput`] with its name and its value here; the
//! dataset, the trainer and the exporter carry it by name (see the guide's "Adding a policy
//! input").

use std::fmt;

use crate::{Goal, OccupancySpec, PolicyOutput, wrap_angle};

/// The most scalars a model may take beside its image.
pub const MAX_AUX: usize = 8;

/// One scalar a policy takes beside its image, known by its name in `formation.aux`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AuxInput {
    /// `delta_phi`: `wrap(phi* - heading)` \[rad\], the heading error the compass gives.
    HeadingError,
    /// `d_star`: the goal's distance d* \[m\].
    DStar,
}

impl AuxInput {
    /// Every scalar input this build knows.
    pub const KNOWN: [AuxInput; 2] = [AuxInput::HeadingError, AuxInput::DStar];

    /// Its name in `formation.aux` (and in datasets).
    pub fn name(self) -> &'static str {
        match self {
            AuxInput::HeadingError => "delta_phi",
            AuxInput::DStar => "d_star",
        }
    }

    /// The input a name stands for, if this build knows it.
    pub fn parse(name: &str) -> Option<AuxInput> {
        AuxInput::KNOWN.into_iter().find(|i| i.name() == name)
    }

    /// Its value for a robot with this heading under this goal.
    pub fn value(self, heading: f64, goal: &Goal) -> f64 {
        match self {
            AuxInput::HeadingError => wrap_angle(goal.phi_star - heading),
            AuxInput::DStar => goal.d_star,
        }
    }
}

/// Why a `formation.aux` declaration cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AuxLayoutError {
    /// A name this build does not know.
    #[error(
        "unknown input {name:?}: this build knows {}; update formation or re-export the model",
        known_names()
    )]
    Unknown {
        /// The name.
        name: String,
    },
    /// A name given twice.
    #[error("input {name:?} is declared twice")]
    Repeated {
        /// The name.
        name: String,
    },
    /// No name at all, or more than [`MAX_AUX`].
    #[error("{count} inputs declared; a model takes 1 to {MAX_AUX} scalars beside its image")]
    Count {
        /// How many were declared.
        count: usize,
    },
}

fn known_names() -> String {
    AuxInput::KNOWN.map(AuxInput::name).join(", ")
}

/// The scalars a model takes beside its image, in its declared order.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct AuxLayout {
    inputs: [AuxInput; MAX_AUX],
    len: usize,
}

impl AuxLayout {
    /// The paper's `(delta_phi, d*)`: what a model that declares nothing takes.
    pub const PAPER: AuxLayout = AuxLayout {
        inputs: [
            AuxInput::HeadingError,
            AuxInput::DStar,
            AuxInput::DStar,
            AuxInput::DStar,
            AuxInput::DStar,
            AuxInput::DStar,
            AuxInput::DStar,
            AuxInput::DStar,
        ],
        len: 2,
    };

    /// The layout of these inputs, in this order.
    pub fn new(inputs: &[AuxInput]) -> Result<AuxLayout, AuxLayoutError> {
        if inputs.is_empty() || inputs.len() > MAX_AUX {
            return Err(AuxLayoutError::Count {
                count: inputs.len(),
            });
        }
        let mut layout = AuxLayout {
            inputs: [AuxInput::DStar; MAX_AUX],
            len: inputs.len(),
        };
        for (k, &input) in inputs.iter().enumerate() {
            if inputs[..k].contains(&input) {
                return Err(AuxLayoutError::Repeated {
                    name: input.name().to_owned(),
                });
            }
            layout.inputs[k] = input;
        }
        Ok(layout)
    }

    /// Parses a `formation.aux` value: names separated by commas, e.g. `delta_phi,d_star`.
    pub fn parse(text: &str) -> Result<AuxLayout, AuxLayoutError> {
        let mut inputs = Vec::new();
        for name in text.split(',').map(str::trim) {
            let input = AuxInput::parse(name).ok_or_else(|| AuxLayoutError::Unknown {
                name: name.to_owned(),
            })?;
            inputs.push(input);
        }
        AuxLayout::new(&inputs)
    }

    /// The inputs, in order.
    pub fn inputs(&self) -> &[AuxInput] {
        &self.inputs[..self.len]
    }

    /// How many scalars: the width of the model's `aux` tensor.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Never true: a layout holds at least one input.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The values for a robot with this heading under this goal, narrowed to `f32`.
    pub fn values(&self, heading: f64, goal: &Goal) -> AuxValues {
        let mut values = AuxValues {
            values: [0.0; MAX_AUX],
            len: self.len,
        };
        for (slot, input) in values.values.iter_mut().zip(self.inputs()) {
            *slot = input.value(heading, goal) as f32;
        }
        values
    }
}

impl Default for AuxLayout {
    fn default() -> AuxLayout {
        AuxLayout::PAPER
    }
}

impl fmt::Display for AuxLayout {
    /// The `formation.aux` value: the names joined by commas.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (k, input) in self.inputs().iter().enumerate() {
            if k > 0 {
                f.write_str(",")?;
            }
            f.write_str(input.name())?;
        }
        Ok(())
    }
}

impl fmt::Debug for AuxLayout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "AuxLayout({self})")
    }
}

/// The scalars fed beside the image, as [`AuxLayout::values`] computes them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AuxValues {
    values: [f32; MAX_AUX],
    len: usize,
}

impl AuxValues {
    /// Values given directly (a test's or a trial's), at most [`MAX_AUX`]; `None` if more.
    pub fn from_slice(values: &[f32]) -> Option<AuxValues> {
        let mut out = AuxValues {
            values: [0.0; MAX_AUX],
            len: values.len(),
        };
        out.values.get_mut(..values.len())?.copy_from_slice(values);
        Some(out)
    }
}

impl std::ops::Deref for AuxValues {
    type Target = [f32];
    fn deref(&self) -> &[f32] {
        &self.values[..self.len]
    }
}

/// The scan's ranges as a model takes them beside its image: the `ranges` input, `[B, sectors]`
/// f32, declared by `formation.ranges = "sectors=K,clip=C"`.
///
/// The beams of the model's LIDAR (`L` of them, beam `b` at body bearing `2 pi b / L`) are
/// grouped into `K` sectors centred on bearings `2 pi s / K`: beam `b` belongs to sector
/// `floor(b K / L + 1/2) mod K`. A sector's value is the mean of `range / d*` over its beams
/// that return (a finite range in `[0, max_range)`), at most `C`; a sector with no return is
/// `C`. Dividing by d* makes the input what the image is: the same formation at any d* looks
/// the same. Reflecting the scene about the robot's heading axis maps sector `s` to
/// `(K - s) mod K`, exactly when `L / K` is an odd whole number (900 beams in 100 sectors of
/// 9, 360 in 120 of 3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeInput {
    /// `K`: sectors, [`RangeInput::MIN_SECTORS`] ..= [`RangeInput::MAX_SECTORS`].
    pub sectors: usize,
    /// `C`: the largest value, in units of d*, in `(0, `[`RangeInput::MAX_CLIP`]`]`.
    pub clip: f32,
}

/// Why a `formation.ranges` declaration cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RangeInputError {
    /// Not `sectors=K,clip=C`.
    #[error(
        "\"{text}\" is not a range input: write \"sectors=K,clip=C\" (K sectors, {min} to {max}; \
         C the largest value in units of d*, above 0 and at most {max_clip})",
        min = RangeInput::MIN_SECTORS,
        max = RangeInput::MAX_SECTORS,
        max_clip = RangeInput::MAX_CLIP
    )]
    Syntax {
        /// The declaration.
        text: String,
    },
    /// A value outside its range.
    #[error(
        "range input {what} = {value} is out of range: sectors must be {min} to {max}, \
         clip above 0 and at most {max_clip}",
        min = RangeInput::MIN_SECTORS,
        max = RangeInput::MAX_SECTORS,
        max_clip = RangeInput::MAX_CLIP
    )]
    Range {
        /// `sectors` or `clip`.
        what: &'static str,
        /// The value found.
        value: String,
    },
    /// More sectors than the LIDAR has beams.
    #[error("a range input of {sectors} sectors needs at least as many LIDAR beams, not {beams}")]
    Beams {
        /// Sectors declared.
        sectors: usize,
        /// Beams of the LIDAR.
        beams: usize,
    },
}

impl RangeInput {
    /// The fewest sectors.
    pub const MIN_SECTORS: usize = 4;
    /// The most sectors (one a degree).
    pub const MAX_SECTORS: usize = 360;
    /// The largest clip, in units of d*.
    pub const MAX_CLIP: f32 = 100.0;

    /// A checked range input.
    pub fn new(sectors: usize, clip: f32) -> Result<RangeInput, RangeInputError> {
        if !(RangeInput::MIN_SECTORS..=RangeInput::MAX_SECTORS).contains(&sectors) {
            return Err(RangeInputError::Range {
                what: "sectors",
                value: sectors.to_string(),
            });
        }
        if !(clip > 0.0 && clip <= RangeInput::MAX_CLIP) {
            return Err(RangeInputError::Range {
                what: "clip",
                value: clip.to_string(),
            });
        }
        Ok(RangeInput { sectors, clip })
    }

    /// Reads `sectors=K,clip=C` (the keys in either order, spaces around them allowed).
    pub fn parse(text: &str) -> Result<RangeInput, RangeInputError> {
        let syntax = || RangeInputError::Syntax {
            text: text.to_owned(),
        };
        let (mut sectors, mut clip) = (None, None);
        for part in text.split(',') {
            let (key, value) = part.split_once('=').ok_or_else(syntax)?;
            let value = value.trim();
            match key.trim() {
                "sectors" if sectors.is_none() => {
                    sectors = Some(value.parse::<usize>().map_err(|_| syntax())?)
                }
                "clip" if clip.is_none() => {
                    clip = Some(value.parse::<f32>().map_err(|_| syntax())?)
                }
                _ => return Err(syntax()),
            }
        }
        match (sectors, clip) {
            (Some(sectors), Some(clip)) => RangeInput::new(sectors, clip),
            _ => Err(syntax()),
        }
    }

    /// Checks that a LIDAR of `beams` beams fills every sector.
    pub fn check_beams(&self, beams: usize) -> Result<(), RangeInputError> {
        if beams < self.sectors {
            return Err(RangeInputError::Beams {
                sectors: self.sectors,
                beams,
            });
        }
        Ok(())
    }

    /// The sector of beam `beam` of `beams`.
    pub fn sector_of(&self, beam: usize, beams: usize) -> usize {
        ((2 * beam * self.sectors + beams) / (2 * beams)) % self.sectors
    }

    /// The sector a reflection about the heading axis maps `sector` to.
    pub fn mirrored(&self, sector: usize) -> usize {
        (self.sectors - sector) % self.sectors
    }
}

impl std::str::FromStr for RangeInput {
    type Err = RangeInputError;
    fn from_str(text: &str) -> Result<RangeInput, RangeInputError> {
        RangeInput::parse(text)
    }
}

impl fmt::Display for RangeInput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "sectors={},clip={}", self.sectors, self.clip)
    }
}

/// The neighbours a robot detects in its own scan, as a model takes them beside its image: the
/// `neighbours` input, `[B, slots, features]` f32, declared by
/// `formation.neighbours = "slots=K,threshold=T,nearest=M[,hidden=1]"` (issue 34).
///
/// Each detection (a body's centre fitted to its returns, in the robot's body frame, x ahead and
/// y to the left) fills one slot with `(x / d*, y / d*, held, 1)`. `held` is 1 where the robot
/// holds that neighbour at d* by the Gabriel rule applied to itself and its detections (witness
/// ratio at least `T`, plus its `M` nearest, within the LIDAR's range: [`crate::GabrielRule`]
/// with no hysteresis), 0 otherwise. Held neighbours come first, nearest first, then the others,
/// nearest first; slots left over are all zeros, and detections past `K` are dropped. Dividing by
/// d* makes the input what the image is: the same formation at any d* looks the same. Reflecting
/// the scene about the robot's heading axis negates every `y` and keeps the order and the flags.
///
/// With `hidden=1` each slot has two more numbers, `(hx, hy)`: the step aside that the pairs of
/// detections the robot hides from each other ask of it (`formation_perception::hidden_pairs`),
/// in the robot's frame and in units of d\*, half of each pair's step on each of its two slots.
/// A pair `d` apart, with weight `w` and unit vector `away` from its line to the robot, asks for
/// `w * 2 (ρ⁴ - 1) / ρ³ * away` with `ρ = d / d*`: the pull the pair would feel, the expert's law
/// on one robot's scan with `unblock_hidden_pairs`. Reflecting the scene negates `hy` too.
///
/// The detection and the rule are `formation_perception::neighbour_input`'s, shared by
/// collection, the agent and the Python package.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NeighbourInput {
    /// `K`: slots, [`NeighbourInput::MIN_SLOTS`] ..= [`NeighbourInput::MAX_SLOTS`].
    pub slots: usize,
    /// `T`: the Gabriel rule's witness-ratio threshold, in `[1, `[`NeighbourInput::MAX_THRESHOLD`]`]`.
    pub threshold: f64,
    /// `M`: the nearest detections always held, at most [`NeighbourInput::MAX_NEAREST`].
    pub nearest: usize,
    /// Whether each slot also carries the step aside its hidden pairs ask for (`hidden=1`).
    pub hidden: bool,
}

/// Why a `formation.neighbours` declaration cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NeighbourInputError {
    /// Not `slots=K,threshold=T,nearest=M[,hidden=1]`.
    #[error(
        "\"{text}\" is not a neighbour input: write \"slots=K,threshold=T,nearest=M\" (K slots, \
         {min} to {max}; T the Gabriel threshold, 1 to {max_threshold}; M the nearest always held, \
         0 to {max_nearest}), and \",hidden=1\" for the step aside of hidden pairs",
        min = NeighbourInput::MIN_SLOTS,
        max = NeighbourInput::MAX_SLOTS,
        max_threshold = NeighbourInput::MAX_THRESHOLD,
        max_nearest = NeighbourInput::MAX_NEAREST
    )]
    Syntax {
        /// The declaration.
        text: String,
    },
    /// A value outside its range.
    #[error(
        "neighbour input {what} = {value} is out of range: slots must be {min} to {max}, \
         threshold 1 to {max_threshold}, nearest 0 to {max_nearest}",
        min = NeighbourInput::MIN_SLOTS,
        max = NeighbourInput::MAX_SLOTS,
        max_threshold = NeighbourInput::MAX_THRESHOLD,
        max_nearest = NeighbourInput::MAX_NEAREST
    )]
    Range {
        /// `slots`, `threshold` or `nearest`.
        what: &'static str,
        /// The value found.
        value: String,
    },
}

impl NeighbourInput {
    /// Numbers per slot: `x / d*`, `y / d*`, `held`, `present`.
    pub const BASE_FEATURES: usize = 4;
    /// Numbers per slot with `hidden=1`: then also `hx`, `hy`.
    pub const HIDDEN_FEATURES: usize = 6;
    /// The fewest slots.
    pub const MIN_SLOTS: usize = 1;
    /// The most slots.
    pub const MAX_SLOTS: usize = 64;
    /// The largest threshold.
    pub const MAX_THRESHOLD: f64 = 4.0;
    /// The most nearest neighbours always held.
    pub const MAX_NEAREST: usize = 8;

    /// A checked neighbour input.
    pub fn new(
        slots: usize,
        threshold: f64,
        nearest: usize,
    ) -> Result<NeighbourInput, NeighbourInputError> {
        if !(NeighbourInput::MIN_SLOTS..=NeighbourInput::MAX_SLOTS).contains(&slots) {
            return Err(NeighbourInputError::Range {
                what: "slots",
                value: slots.to_string(),
            });
        }
        if !(1.0..=NeighbourInput::MAX_THRESHOLD).contains(&threshold) {
            return Err(NeighbourInputError::Range {
                what: "threshold",
                value: threshold.to_string(),
            });
        }
        if nearest > NeighbourInput::MAX_NEAREST {
            return Err(NeighbourInputError::Range {
                what: "nearest",
                value: nearest.to_string(),
            });
        }
        Ok(NeighbourInput {
            slots,
            threshold,
            nearest,
            hidden: false,
        })
    }

    /// The same input, with or without the hidden pairs' step aside in each slot.
    pub fn with_hidden(self, hidden: bool) -> NeighbourInput {
        NeighbourInput { hidden, ..self }
    }

    /// Numbers per slot: [`NeighbourInput::HIDDEN_FEATURES`] with `hidden=1`, else
    /// [`NeighbourInput::BASE_FEATURES`].
    pub fn features(&self) -> usize {
        if self.hidden {
            NeighbourInput::HIDDEN_FEATURES
        } else {
            NeighbourInput::BASE_FEATURES
        }
    }

    /// The scenarios' default rule ([`crate::GabrielRule::DEFAULT_THRESHOLD`],
    /// [`crate::GabrielRule::DEFAULT_NEAREST`]) over `slots` slots.
    pub fn with_default_rule(slots: usize) -> Result<NeighbourInput, NeighbourInputError> {
        NeighbourInput::new(
            slots,
            crate::GabrielRule::DEFAULT_THRESHOLD,
            crate::GabrielRule::DEFAULT_NEAREST,
        )
    }

    /// Reads `slots=K,threshold=T,nearest=M`, optionally `,hidden=0|1` (the keys in any order,
    /// spaces around them allowed).
    pub fn parse(text: &str) -> Result<NeighbourInput, NeighbourInputError> {
        let syntax = || NeighbourInputError::Syntax {
            text: text.to_owned(),
        };
        let (mut slots, mut threshold, mut nearest, mut hidden) = (None, None, None, None);
        for part in text.split(',') {
            let (key, value) = part.split_once('=').ok_or_else(syntax)?;
            let value = value.trim();
            match key.trim() {
                "slots" if slots.is_none() => {
                    slots = Some(value.parse::<usize>().map_err(|_| syntax())?)
                }
                "threshold" if threshold.is_none() => {
                    threshold = Some(value.parse::<f64>().map_err(|_| syntax())?)
                }
                "nearest" if nearest.is_none() => {
                    nearest = Some(value.parse::<usize>().map_err(|_| syntax())?)
                }
                "hidden" if hidden.is_none() => {
                    hidden = Some(match value {
                        "0" => false,
                        "1" => true,
                        _ => return Err(syntax()),
                    })
                }
                _ => return Err(syntax()),
            }
        }
        match (slots, threshold, nearest) {
            (Some(slots), Some(threshold), Some(nearest)) => {
                Ok(NeighbourInput::new(slots, threshold, nearest)?
                    .with_hidden(hidden.unwrap_or(false)))
            }
            _ => Err(syntax()),
        }
    }

    /// The width of one sample's input: `slots * features()`.
    pub fn len(&self) -> usize {
        self.slots * self.features()
    }

    /// Never true: an input has at least one slot.
    pub fn is_empty(&self) -> bool {
        self.slots == 0
    }

    /// The Gabriel rule the `held` flags follow, for a LIDAR that reaches `sensing_range` metres.
    pub fn rule(&self, sensing_range: f64) -> crate::GabrielRule {
        crate::GabrielRule {
            sensing_range,
            nearest: self.nearest,
            threshold: self.threshold,
            hysteresis: 0.0,
        }
    }
}

impl std::str::FromStr for NeighbourInput {
    type Err = NeighbourInputError;
    fn from_str(text: &str) -> Result<NeighbourInput, NeighbourInputError> {
        NeighbourInput::parse(text)
    }
}

impl fmt::Display for NeighbourInput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "slots={},threshold={},nearest={}",
            self.slots, self.threshold, self.nearest
        )?;
        // Absent while off, so a declaration of four numbers a slot reads as it always has.
        if self.hidden {
            write!(f, ",hidden=1")?;
        }
        Ok(())
    }
}

/// What a model takes and answers: its image, its scalars and its output, as its metadata
/// declares them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolicyIo {
    /// The occupancy image it takes, rendered from the robot's own scan.
    pub image: OccupancySpec,
    /// The scalars beside the image.
    pub aux: AuxLayout,
    /// The scan's ranges beside the image, if the model takes them.
    pub ranges: Option<RangeInput>,
    /// The neighbours detected in the scan, beside the image, if the model takes them.
    pub neighbours: Option<NeighbourInput>,
    /// What its one output means.
    pub output: PolicyOutput,
    /// Its training speed \[m/s\]: a `wheels` output is scaled by `v* / v_train`.
    pub v_train: f64,
}

/// One decision's inputs, as a model's [`PolicyIo`] declares them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolicyInput<'a> {
    /// The occupancy image, `size_px * size_px` cells (0.0 or 1.0), row-major.
    pub image: &'a [f32],
    /// The scalars the model declares, in order.
    pub aux: &'a [f32],
    /// The scan's ranges, one a sector; empty for a model that takes none.
    pub ranges: &'a [f32],
    /// The detected neighbours, [`NeighbourInput::features`] a slot; empty for a model that
    /// takes none.
    pub neighbours: &'a [f32],
}

impl<'a> PolicyInput<'a> {
    /// The inputs of a model that takes no ranges: its image and its scalars.
    pub fn image_and_aux(image: &'a [f32], aux: &'a [f32]) -> PolicyInput<'a> {
        PolicyInput {
            image,
            aux,
            ranges: &[],
            neighbours: &[],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn goal(phi_star: f64, d_star: f64) -> Goal {
        Goal::new(phi_star, d_star, 0.5)
    }

    #[test]
    fn the_paper_layout_is_the_wrapped_heading_error_then_d_star() {
        let values = AuxLayout::PAPER.values(3.0, &goal(-3.0, 1.5));
        assert_eq!(&*values, &[wrap_angle(-6.0) as f32, 1.5]);
        assert_eq!(AuxLayout::PAPER.to_string(), "delta_phi,d_star");
        assert_eq!(AuxLayout::parse("delta_phi,d_star"), Ok(AuxLayout::PAPER));
        assert_eq!(AuxLayout::default(), AuxLayout::PAPER);
    }

    #[test]
    fn a_declared_order_is_kept() {
        let layout = AuxLayout::parse("d_star, delta_phi").unwrap();
        assert_eq!(layout.inputs(), &[AuxInput::DStar, AuxInput::HeadingError]);
        assert_eq!(&*layout.values(0.0, &goal(0.25, 2.0)), &[2.0, 0.25]);
        assert_ne!(layout, AuxLayout::PAPER);
    }

    #[test]
    fn bad_declarations_are_refused_naming_the_fault() {
        let unknown = AuxLayout::parse("delta_phi,speed").unwrap_err();
        assert_eq!(
            unknown,
            AuxLayoutError::Unknown {
                name: "speed".into()
            }
        );
        assert!(
            unknown.to_string().contains("delta_phi, d_star"),
            "{unknown}"
        );
        assert!(matches!(
            AuxLayout::parse("d_star,d_star"),
            Err(AuxLayoutError::Repeated { .. })
        ));
        assert!(matches!(
            AuxLayout::parse(""),
            Err(AuxLayoutError::Unknown { .. })
        ));
        assert_eq!(AuxLayout::new(&[]), Err(AuxLayoutError::Count { count: 0 }));
        assert_eq!(
            AuxLayout::new(&[AuxInput::DStar; MAX_AUX + 1]),
            Err(AuxLayoutError::Count { count: MAX_AUX + 1 })
        );
    }

    #[test]
    fn a_range_input_reads_back_what_it_writes_and_refuses_bad_values() {
        let ranges = RangeInput::parse("sectors=100, clip=3").unwrap();
        assert_eq!(
            ranges,
            RangeInput {
                sectors: 100,
                clip: 3.0
            }
        );
        assert_eq!(RangeInput::parse(&ranges.to_string()), Ok(ranges));
        assert_eq!(
            RangeInput::parse("clip=2.5,sectors=120").unwrap().sectors,
            120
        );
        for bad in [
            "",
            "sectors=100",
            "sectors=100,clip=3,x=1",
            "sectors=1e2,clip=3",
            "sectors=100,sectors=100",
        ] {
            assert!(
                matches!(RangeInput::parse(bad), Err(RangeInputError::Syntax { .. })),
                "{bad}"
            );
        }
        for bad in [
            "sectors=3,clip=3",
            "sectors=361,clip=3",
            "sectors=100,clip=0",
            "sectors=100,clip=NaN",
            "sectors=100,clip=101",
        ] {
            assert!(
                matches!(RangeInput::parse(bad), Err(RangeInputError::Range { .. })),
                "{bad}"
            );
        }
        assert!(ranges.check_beams(100).is_ok());
        assert!(matches!(
            ranges.check_beams(90),
            Err(RangeInputError::Beams { .. })
        ));
    }

    #[test]
    fn sectors_are_centred_and_mirror_exactly_when_each_holds_an_odd_number_of_beams() {
        let ranges = RangeInput::new(100, 3.0).unwrap();
        // 900 beams: sector 0 holds beams -4..=4, sector 1 beams 5..=13.
        let sectors: Vec<usize> = (0..900).map(|b| ranges.sector_of(b, 900)).collect();
        assert_eq!(&sectors[..6], &[0, 0, 0, 0, 0, 1]);
        assert_eq!(&sectors[895..], &[99, 0, 0, 0, 0]);
        for s in 0..100 {
            assert_eq!(sectors.iter().filter(|&&x| x == s).count(), 9);
        }
        // The reflection b -> -b maps each beam's sector to its mirror.
        for b in 0..900 {
            let reflected = (900 - b) % 900;
            assert_eq!(sectors[reflected], ranges.mirrored(sectors[b]));
        }
    }

    #[test]
    fn a_neighbour_input_reads_back_what_it_writes_and_refuses_bad_values() {
        let input = NeighbourInput::parse("slots=16, threshold=1.3, nearest=2").unwrap();
        assert_eq!(input, NeighbourInput::with_default_rule(16).unwrap());
        assert_eq!(NeighbourInput::parse(&input.to_string()), Ok(input));
        assert_eq!(input.len(), 64);
        assert_eq!(input.to_string(), "slots=16,threshold=1.3,nearest=2");
        let hidden = NeighbourInput::parse("hidden=1,slots=16,threshold=1.3,nearest=2").unwrap();
        assert_eq!(hidden, input.with_hidden(true));
        assert_eq!((hidden.features(), hidden.len()), (6, 96));
        assert_eq!(
            hidden.to_string(),
            "slots=16,threshold=1.3,nearest=2,hidden=1"
        );
        assert_eq!(NeighbourInput::parse(&hidden.to_string()), Ok(hidden));
        assert_eq!(
            NeighbourInput::parse("slots=16,threshold=1.3,nearest=2,hidden=0"),
            Ok(input)
        );
        let rule = input.rule(10.0);
        assert_eq!(
            (rule.threshold, rule.nearest, rule.hysteresis),
            (1.3, 2, 0.0)
        );
        for bad in [
            "",
            "slots=16",
            "slots=16,threshold=1.3",
            "slots=16,threshold=1.3,nearest=2,x=1",
            "slots=16,slots=16,nearest=2",
            "slots=1.5,threshold=1.3,nearest=2",
            "slots=16,threshold=1.3,nearest=2,hidden=yes",
            "slots=16,threshold=1.3,nearest=2,hidden=1,hidden=1",
        ] {
            assert!(
                matches!(
                    NeighbourInput::parse(bad),
                    Err(NeighbourInputError::Syntax { .. })
                ),
                "{bad}"
            );
        }
        for bad in [
            "slots=0,threshold=1.3,nearest=2",
            "slots=65,threshold=1.3,nearest=2",
            "slots=16,threshold=0.9,nearest=2",
            "slots=16,threshold=NaN,nearest=2",
            "slots=16,threshold=1.3,nearest=9",
        ] {
            assert!(
                matches!(
                    NeighbourInput::parse(bad),
                    Err(NeighbourInputError::Range { .. })
                ),
                "{bad}"
            );
        }
    }

    #[test]
    fn values_given_directly_keep_their_length() {
        assert_eq!(&*AuxValues::from_slice(&[0.0, 1.0]).unwrap(), &[0.0, 1.0]);
        assert!(AuxValues::from_slice(&[0.0; MAX_AUX + 1]).is_none());
    }
}
