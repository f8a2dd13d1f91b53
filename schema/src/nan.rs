//! Reading `null` as NaN: serde_json writes a non-finite float as `null`, so a float that may be
//! NaN reads through these.

use formation_proto::{Pose, WheelCmd};
use serde::{Deserialize, Deserializer};

/// A float written as a number, or as `null` for NaN.
#[derive(Deserialize)]
#[serde(transparent)]
struct Float(#[serde(deserialize_with = "float")] f64);

/// A float, `null` reading as NaN.
pub fn float<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// A list of floats, `null` reading as NaN.
pub fn floats<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
    Ok(Vec::<Float>::deserialize(d)?
        .into_iter()
        .map(|x| x.0)
        .collect())
}

/// [`Pose`]'s fields, each read with [`float`].
#[derive(Deserialize)]
struct PoseIn {
    x: Float,
    y: Float,
    theta: Float,
}

/// [`WheelCmd`]'s fields, each read with [`float`].
#[derive(Deserialize)]
struct WheelCmdIn {
    left: Float,
    right: Float,
}

/// Rows of poses, `null` coordinates reading as NaN.
pub fn pose_rows<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Vec<Pose>>, D::Error> {
    rows(d, |p: PoseIn| Pose {
        x: p.x.0,
        y: p.y.0,
        theta: p.theta.0,
    })
}

/// Rows of wheel commands, `null` speeds reading as NaN.
pub fn command_rows<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Vec<WheelCmd>>, D::Error> {
    rows(d, |c: WheelCmdIn| WheelCmd {
        left: c.left.0,
        right: c.right.0,
    })
}

/// Rows of `In` (a value's fields, each read with [`float`]), each made a value by `make`.
fn rows<'de, D: Deserializer<'de>, In: Deserialize<'de>, T>(
    d: D,
    make: impl Fn(In) -> T,
) -> Result<Vec<Vec<T>>, D::Error> {
    Ok(Vec::<Vec<In>>::deserialize(d)?
        .into_iter()
        .map(|row| row.into_iter().map(&make).collect())
        .collect())
}
