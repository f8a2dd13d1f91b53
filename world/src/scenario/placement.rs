//! How a run's robots are placed: uniform in the disc at a minimum spacing, the team connected
//! through sensing range, with a lattice fallback that always ends.

use super::*;

/// How far a robot senses its team mates \[m\]: the Gabriel rule's sensing range, else the
/// LIDAR's range.
pub(super) fn sensing_range(rule: &NeighbourRule, world: &WorldConfig) -> f64 {
    match rule {
        NeighbourRule::AllPairs => world.lidar.max_range,
        NeighbourRule::Gabriel(g) => g.sensing_range,
    }
}

/// Positions of `n` robots uniform in the disc, each at least `min_spacing` from the others, the
/// team connected through `range` (every robot reaches every other through robots at most `range`
/// apart).
///
/// Sequential rejection: each robot is redrawn until it keeps its distance from those already placed;
/// if one cannot be placed in [`POSITION_ATTEMPTS_PER_ROBOT`] draws, or the team is not connected, the
/// whole team starts over, at most [`PLACEMENT_RESTARTS`] times. For a crowded or a wide disc where this
/// keeps failing (validation guarantees that a spacing-`min_spacing` hexagonal lattice has `n` sites in
/// the disc, and that `min_spacing <= range`), `n` lattice sites are grown at random as a connected patch
/// instead, so the function always ends. The paper's settings accept nearly every draw, and a team
/// that fits in a disc of diameter `range` is always connected, so the paper's runs draw exactly what
/// they drew before teams had to be connected.
pub(super) fn place_robots(
    rng: &mut ChaCha8Rng,
    n: usize,
    init: &InitialConditions,
    range: f64,
) -> Vec<(f64, f64)> {
    let spacing_sq = init.min_spacing * init.min_spacing;
    let mut placed: Vec<(f64, f64)> = Vec::with_capacity(n);
    for _ in 0..PLACEMENT_RESTARTS {
        placed.clear();
        'robots: for _ in 0..n {
            for _ in 0..POSITION_ATTEMPTS_PER_ROBOT {
                let r = init.disc_radius * rng.random::<f64>().sqrt();
                let angle = rng.random_range(0.0..TAU);
                let candidate = (r * angle.cos(), r * angle.sin());
                let clear = placed.iter().all(|&(x, y)| {
                    let (dx, dy) = (candidate.0 - x, candidate.1 - y);
                    dx * dx + dy * dy >= spacing_sq
                });
                if clear {
                    placed.push(candidate);
                    continue 'robots;
                }
            }
            break;
        }
        if placed.len() == n && connected_within(&placed, range) {
            return placed;
        }
    }
    connected_lattice_patch(rng, n, init, range)
}

/// `n` sites of the spacing-`min_spacing` hexagonal lattice in the disc, grown from a random site by
/// adding random sites within `range` of the patch, so the patch is connected through `range`.
pub(super) fn connected_lattice_patch(
    rng: &mut ChaCha8Rng,
    n: usize,
    init: &InitialConditions,
    range: f64,
) -> Vec<(f64, f64)> {
    let mut free = lattice_sites(init.disc_radius, init.min_spacing, usize::MAX);
    let mut placed: Vec<(f64, f64)> = Vec::with_capacity(n);
    let range_sq = range * range;
    while placed.len() < n && !free.is_empty() {
        let reachable: Vec<usize> = (0..free.len())
            .filter(|&s| {
                placed.is_empty()
                    || placed.iter().any(|&(x, y)| {
                        let (dx, dy) = (free[s].0 - x, free[s].1 - y);
                        dx * dx + dy * dy <= range_sq
                    })
            })
            .collect();
        // A lattice in a disc is connected at its spacing, which validation keeps <= range; should
        // it not be, any free site keeps the function total.
        let pick = if reachable.is_empty() {
            rng.random_range(0..free.len())
        } else {
            reachable[rng.random_range(0..reachable.len())]
        };
        placed.push(free.swap_remove(pick));
    }
    placed
}

/// Sites of a hexagonal lattice with spacing `spacing`, centred at the origin, inside a disc of
/// `radius`; stops after `limit` sites.
pub(super) fn lattice_sites(radius: f64, spacing: f64, limit: usize) -> Vec<(f64, f64)> {
    let row_height = spacing * 3f64.sqrt() / 2.0;
    let rows = (radius / row_height).floor() as i64;
    let columns = (radius / spacing).ceil() as i64 + 1;
    let mut sites = Vec::new();
    for row in -rows..=rows {
        let y = row as f64 * row_height;
        let shift = if row.rem_euclid(2) == 1 { 0.5 } else { 0.0 };
        for column in -columns..=columns {
            let x = (column as f64 + shift) * spacing;
            if x * x + y * y <= radius * radius {
                sites.push((x, y));
                if sites.len() >= limit {
                    return sites;
                }
            }
        }
    }
    sites
}
