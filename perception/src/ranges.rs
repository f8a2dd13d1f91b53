//! The scan's ranges as a model takes them beside its image ([`RangeInput`]): the beams grouped
//! into sectors, each the mean range of its returning beams in units of d*.
//!
//! The single computation of the `ranges` input: collection (`formation_expert::collect`) and the
//! running agent (`formation_robot_agent::decision`) both call [`pool`], so a policy sees at run
//! time exactly the values it was trained on.
//!
//! Where the image resolves a neighbour to one cell (10 cm at d* = 1.5 m in the shipped window),
//! a sector's mean over its beams resolves the nearest surface to about the range noise over the
//! square root of its beam count (1 cm for 9 beams at σ = 3 cm).

use formation_proto::{LidarSpec, RangeInput};

/// Fills `out` with the `ranges` input of one scan under the goal spacing `d_star` \[m\]: sector
/// `s` is the mean of `range / d_star` over the beams of sector `s` that return (a finite range
/// in `[0, max_range)`), at most `spec.clip`; a sector where no beam returns is `spec.clip`. The
/// mean is taken in f64 and rounded to f32 once.
///
/// # Panics
///
/// If `out.len() != spec.sectors`, `scan.len() != lidar.beams` or `lidar.beams < spec.sectors`:
/// buffers are sized by the caller from the same settings, and the model's contract is checked
/// against its LIDAR when it loads, so a mismatch is a programming error, not bad input.
pub fn pool(scan: &[f32], lidar: &LidarSpec, spec: &RangeInput, d_star: f64, out: &mut [f32]) {
    assert_eq!(
        out.len(),
        spec.sectors,
        "ranges buffer must hold one value per sector"
    );
    assert_eq!(
        scan.len(),
        lidar.beams,
        "scan must have one range per configured LIDAR beam"
    );
    assert!(
        lidar.beams >= spec.sectors,
        "every sector needs at least one beam"
    );
    let mut sums = [0.0f64; RangeInput::MAX_SECTORS];
    let mut counts = [0u32; RangeInput::MAX_SECTORS];
    for (beam, &range) in scan.iter().enumerate() {
        let range = f64::from(range);
        // Written so that NaN fails the test too.
        if !(range >= 0.0 && range < lidar.max_range) {
            continue;
        }
        let sector = spec.sector_of(beam, lidar.beams);
        sums[sector] += range;
        counts[sector] += 1;
    }
    let clip = f64::from(spec.clip);
    for ((value, &sum), &count) in out.iter_mut().zip(&sums).zip(&counts) {
        *value = if count == 0 {
            spec.clip
        } else {
            (sum / f64::from(count) / d_star).min(clip) as f32
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lidar(beams: usize) -> LidarSpec {
        LidarSpec {
            beams,
            max_range: 10.0,
        }
    }

    #[test]
    fn a_sector_is_the_mean_of_its_returning_beams_in_units_of_d_star() {
        let spec = RangeInput::new(100, 3.0).unwrap();
        let mut scan = vec![10.0f32; 900]; // nothing returns
        // Sector 0 holds beams -4..=4: two return.
        scan[0] = 1.0;
        scan[898] = 1.5;
        // Sector 1 holds beams 5..=13: one NaN, one negative, one beyond range, one return.
        scan[5] = f32::NAN;
        scan[6] = -1.0;
        scan[7] = 11.0;
        scan[8] = 0.75;
        // Sector 50 returns far beyond the clip.
        scan[450] = 9.0;
        let mut out = vec![0.0; 100];
        pool(&scan, &lidar(900), &spec, 0.5, &mut out);
        assert_eq!(out[0], 2.5);
        assert_eq!(out[1], 1.5);
        assert_eq!(out[50], 3.0);
        assert_eq!(out[2], 3.0, "no return is the clip");
        assert_eq!(out.iter().filter(|&&v| v < 3.0).count(), 2);
    }

    #[test]
    fn a_reflected_scan_gives_the_mirrored_sectors() {
        let spec = RangeInput::new(120, 4.0).unwrap();
        let scan: Vec<f32> = (0..360)
            .map(|b| 0.5 + (b as f32 * 0.37).sin().abs() * 3.0)
            .collect();
        let reflected: Vec<f32> = (0..360).map(|b| scan[(360 - b) % 360]).collect();
        let (mut out, mut out_reflected) = (vec![0.0; 120], vec![0.0; 120]);
        pool(&scan, &lidar(360), &spec, 1.2, &mut out);
        pool(&reflected, &lidar(360), &spec, 1.2, &mut out_reflected);
        for s in 0..120 {
            assert_eq!(out_reflected[spec.mirrored(s)], out[s], "sector {s}");
        }
    }

    #[test]
    fn the_same_formation_at_another_d_star_gives_the_same_values() {
        let spec = RangeInput::new(100, 3.0).unwrap();
        let scan: Vec<f32> = (0..900).map(|b| 1.0 + (b % 7) as f32 * 0.25).collect();
        let doubled: Vec<f32> = scan.iter().map(|r| r * 2.0).collect();
        let (mut out, mut out_doubled) = (vec![0.0; 100], vec![0.0; 100]);
        let far = LidarSpec {
            max_range: 20.0,
            ..lidar(900)
        };
        pool(&scan, &far, &spec, 1.0, &mut out);
        pool(&doubled, &far, &spec, 2.0, &mut out_doubled);
        assert_eq!(out, out_doubled);
    }
}
