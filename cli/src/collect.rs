//! `formation collect`: expert demonstrations into a dataset (the paper's 110,160 samples with
//! `scenarios/collect.toml`).

use anyhow::Context;
use formation_expert::collect::{CollectOptions, check_one_v_star, collect};
use formation_proto::{BeyondWindow, OccupancySpec};
use formation_trainer_bridge::dataset::{DatasetHeader, DatasetWriter};
use formation_world::Scenario;

use crate::args::CollectArgs;
use crate::eval::progress_bar;

/// The occupancy settings named on the command line, validated.
pub fn occupancy_from_args(
    size_px: usize,
    resolution: f64,
    beyond: &str,
    scale_d_star: Option<f64>,
) -> anyhow::Result<OccupancySpec> {
    let beyond = BeyondWindow::parse(beyond)
        .with_context(|| format!("--beyond must be `drop` or `border`, got `{beyond}`"))?;
    if size_px != 50 {
        anyhow::bail!(
            "--size-px must be 50: the paper's network takes 50 x 50 images (got {size_px})"
        );
    }
    if !(resolution.is_finite() && resolution > 0.0) {
        anyhow::bail!(
            "--resolution must be a positive number of metres per cell (got {resolution})"
        );
    }
    if let Some(reference) = scale_d_star
        && !(reference.is_finite() && reference > 0.0)
    {
        anyhow::bail!(
            "--scale-d-star must be a positive d* in metres at which cells are --resolution wide \
             (got {reference})"
        );
    }
    Ok(OccupancySpec {
        size_px,
        resolution_m: resolution,
        beyond,
        d_star_ref_m: scale_d_star,
    })
}

/// `formation collect`.
pub fn collect_command(args: &CollectArgs) -> anyhow::Result<()> {
    let scenario = Scenario::from_path(&args.scenario)?;
    // Before the dataset is created, so that a refusal leaves nothing behind.
    check_one_v_star(&scenario)?;
    let occupancy = occupancy_from_args(
        args.size_px,
        args.resolution,
        &args.beyond,
        args.scale_d_star,
    )?;
    let mut opts = CollectOptions::for_scenario(&scenario);
    opts.occupancy = occupancy;
    opts.gains = args.labels.shape(opts.gains);
    opts.gains.unblock_hidden_pairs = args.unblock_hidden_pairs;
    opts.ranges = args.ranges;
    opts.neighbours = args.neighbours;
    opts.own_scan_labels = args.own_scan_labels;
    if let Some(runs) = args.runs {
        opts.runs = runs;
    }
    if let Some(seed) = args.seed {
        opts.base_seed = seed;
    }
    if opts.runs == 0 {
        anyhow::bail!("--runs must be at least 1");
    }
    let spec0 = scenario.run_spec(opts.base_seed, 0);
    if occupancy.beyond == BeyondWindow::Border
        && spec0.world.lidar.max_range <= occupancy.window_m() / 2.0
    {
        anyhow::bail!(
            "border rendering needs a LIDAR range beyond the window: lidar.max_range is {} m, the window half-side {} m",
            spec0.world.lidar.max_range,
            occupancy.window_m() / 2.0
        );
    }
    let header = DatasetHeader::new(
        occupancy,
        spec0.world.simulated_lidar(),
        spec0.v_star,
        opts.base_seed,
        scenario.name().to_owned(),
    )
    .with_ranges(opts.ranges)
    .with_neighbours(opts.neighbours)
    .with_labels(opts.label_law());
    let mut writer = DatasetWriter::create(&args.out, header)
        .with_context(|| format!("creating dataset {}", args.out.display()))?;
    let bar = progress_bar(opts.runs, "collect");
    let report = collect(&opts, &mut writer, &mut |runs, _| {
        bar.set_position(runs as u64)
    })?;
    bar.finish_and_clear();
    let manifest = writer.finish()?;
    println!(
        "collected {} samples from {} runs in {:.1} s ({:.0} samples/s) into {} (dataset {})",
        report.samples,
        report.runs,
        report.elapsed.as_secs_f64(),
        report.samples_per_sec,
        args.out.display(),
        manifest.dataset_id
    );
    Ok(())
}
