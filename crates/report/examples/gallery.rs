//! Draws every kind of picture into a directory, for looking at them:
//! `cargo run -p ferret-report --example gallery -- OUTDIR [png|svg]`.
//!
//! Uses the hand-built test house, a generated house (with its occupancy grid and shortest
//! paths), synthetic costs and curves, and, when `FERRET_PROCTHOR_DIR` is set, real ProcTHOR
//! houses. Invented data is labelled as such (`synthetic A`, ...): no picture made here carries
//! the name of a model or strategy that did not produce it.

#[path = "../tests/common/mod.rs"]
mod common;

use std::path::{Path, PathBuf};

use ferret_report::{
    CurvePanel, PlanOptions, PlanPath, Rgb, TrajectoryOptions, TrajectoryPanel, ViolinOptions,
    draw_choice_shares, draw_curve_panels, draw_floor_plan, draw_trajectories, draw_violins,
};
use ferret_world::distance::build;
use ferret_world::{GridParams, House, Place};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

type BoxResult<T> = Result<T, Box<dyn std::error::Error>>;

/// Greedy tour: nearest unsearched container until `goal` is searched.
fn greedy(house: &House, d: &ferret_world::Distances, goal: usize) -> (Vec<usize>, f64) {
    let mut at = Place::Start;
    let mut left: Vec<usize> = (0..house.containers.len()).collect();
    let (mut order, mut cost) = (Vec::new(), 0.0);
    while let Some((k, &c)) = left.iter().enumerate().min_by(|a, b| {
        d.between(at, Place::Container(*a.1))
            .total_cmp(&d.between(at, Place::Container(*b.1)))
    }) {
        cost += d.between(at, Place::Container(c));
        order.push(c);
        left.remove(k);
        at = Place::Container(c);
        if c == goal {
            break;
        }
    }
    (order, cost)
}

fn walk(d: &ferret_world::Distances, order: &[usize]) -> Vec<ferret_world::Point> {
    let mut at = Place::Start;
    let mut pts = Vec::new();
    for &c in order {
        if let Some(p) = d.path(at, Place::Container(c)) {
            pts.extend(p);
        }
        at = Place::Container(c);
    }
    pts
}

fn house_figures(house: &House, dir: &Path, stem: &str, ext: &str) -> BoxResult<()> {
    let (grid, d) = build(house, &GridParams::default())?;
    let n = house.containers.len();
    let goal = n / 2;
    let free = |p| grid.cell_of(p).is_some_and(|c| grid.is_free(c));
    let path = d
        .path(Place::Start, Place::Container(goal))
        .unwrap_or_default();
    let opts = PlanOptions {
        paths: vec![PlanPath {
            label: format!("shortest path: start → {}", house.container_label(goal)),
            color: Rgb::palette(3),
            points: path,
        }],
        ..PlanOptions::default()
    };
    draw_floor_plan(house, &opts, &dir.join(format!("{stem}-plan.{ext}")))?;
    let occ = PlanOptions {
        occupancy: Some(&free),
        container_labels: false,
        title: Some(format!("{} — occupancy grid", house.name)),
        ..PlanOptions::default()
    };
    draw_floor_plan(house, &occ, &dir.join(format!("{stem}-grid.{ext}")))?;

    let (g_order, g_cost) = greedy(house, &d, goal);
    let direct = vec![goal];
    let two = vec![(goal + 1) % n, goal];
    let two_cost = d.between(Place::Start, Place::Container(two[0]))
        + d.between(Place::Container(two[0]), Place::Container(goal));
    let panels = vec![
        TrajectoryPanel {
            title: "optimistic+greedy".into(),
            cost_m: g_cost,
            path: walk(&d, &g_order),
            searched: g_order,
            goals: vec![goal],
            goal_labels: Vec::new(),
            destination: None,
            color: None,
            team_paths: Vec::new(),
            searched_by: Vec::new(),
        },
        TrajectoryPanel {
            title: "example: a two-stop search".into(),
            cost_m: two_cost,
            path: walk(&d, &two),
            searched: two,
            goals: vec![goal],
            goal_labels: Vec::new(),
            destination: None,
            color: None,
            team_paths: Vec::new(),
            searched_by: Vec::new(),
        },
        TrajectoryPanel {
            title: "oracle".into(),
            cost_m: d.between(Place::Start, Place::Container(goal)),
            path: walk(&d, &direct),
            searched: direct,
            goals: vec![goal],
            goal_labels: Vec::new(),
            destination: None,
            color: None,
            team_paths: Vec::new(),
            searched_by: Vec::new(),
        },
    ];
    let topts = TrajectoryOptions {
        title: Some(format!(
            "{} — target in the {}",
            house.name,
            house.containers[goal].object_type.words()
        )),
        ..TrajectoryOptions::default()
    };
    draw_trajectories(
        house,
        &panels,
        &topts,
        &dir.join(format!("{stem}-trajectories.{ext}")),
    )?;
    Ok(())
}

fn charts(dir: &Path, ext: &str) -> BoxResult<()> {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let names = [
        "synthetic A",
        "synthetic B",
        "synthetic C",
        "synthetic D",
        "synthetic E",
        "synthetic F",
    ];
    let series: Vec<(String, Vec<f64>)> = names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let scale = 28.0 - 3.0 * i as f64;
            let v = (0..150)
                .map(|_| {
                    let u: f64 = rng.random();
                    (-(1.0 - u).ln() * scale + rng.random::<f64>() * 3.0).min(140.0)
                })
                .collect();
            (n.to_string(), v)
        })
        .collect();
    draw_violins(
        &series,
        &ViolinOptions {
            title: "Synthetic costs (invented data)".into(),
            ..ViolinOptions::default()
        },
        &dir.join(format!("violins.{ext}")),
    )?;

    let k: Vec<f64> = (1..=100).map(f64::from).collect();
    let avg = |base: f64, speed: f64| {
        k.iter()
            .map(|&k| (k, base + 40.0 * (-k / speed).exp()))
            .collect::<Vec<_>>()
    };
    let reg = |slope: f64, speed: f64| {
        k.iter()
            .map(|&k| (k, slope * speed * (1.0 - (-k / speed).exp()) + 2.0 * k))
            .collect::<Vec<_>>()
    };
    let panels = vec![
        CurvePanel {
            title: "Average cost".into(),
            x_label: "trials k".into(),
            y_label: "average cost over trials 1..k (m)".into(),
            series: vec![
                ("synthetic curve 1".into(), avg(24.7, 30.0)),
                ("synthetic curve 2".into(), avg(23.1, 12.0)),
            ],
            marks_at: vec![20.0, 50.0, 100.0],
        },
        CurvePanel {
            title: "Cumulative regret".into(),
            x_label: "trials k".into(),
            y_label: "cumulative regret (m)".into(),
            series: vec![
                ("synthetic curve 1".into(), reg(8.0, 40.0)),
                ("synthetic curve 2".into(), reg(6.0, 20.0)),
            ],
            marks_at: vec![20.0, 50.0, 100.0],
        },
    ];
    draw_curve_panels(&panels, &dir.join(format!("curves.{ext}")))?;

    let strategies = &names[..5];
    let shares: Vec<(String, Vec<f64>)> = strategies
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let v = k
                .iter()
                .map(|&k| {
                    let w: Vec<f64> = (0..5)
                        .map(|j| {
                            if j == 2 {
                                1.0 + k / 8.0
                            } else {
                                1.0 + 0.2 * j as f64
                            }
                        })
                        .collect();
                    w[i] / w.iter().sum::<f64>()
                })
                .collect();
            (n.to_string(), v)
        })
        .collect();
    draw_choice_shares(
        "Synthetic choice shares (invented data)",
        "trials k",
        &k,
        &shares,
        &dir.join(format!("shares.{ext}")),
    )?;
    Ok(())
}

fn main() -> BoxResult<()> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(args.next().unwrap_or_else(|| "gallery".into()));
    let ext = args.next().unwrap_or_else(|| "png".into());
    std::fs::create_dir_all(&dir)?;
    let small = common::small_house();
    draw_floor_plan(
        &small,
        &PlanOptions::default(),
        &dir.join(format!("small-plan.{ext}")),
    )?;
    for (i, scene) in ferret_world::generate::default_scenes(3, 1)?
        .iter()
        .enumerate()
    {
        house_figures(&scene.house, &dir, &format!("generated{i}"), &ext)?;
    }
    if let Some(data) = std::env::var_os("FERRET_PROCTHOR_DIR") {
        let file = Path::new(&data).join("multiroom-val150.jsonl.gz");
        let opts = ferret_world::procthor::LoadOptions {
            shard: None,
            range: "0..3".parse()?,
            ..Default::default()
        };
        for (i, scene) in ferret_world::procthor::load_scenes(&file, &opts)?
            .scenes
            .iter()
            .enumerate()
        {
            house_figures(&scene.house, &dir, &format!("procthor{i}"), &ext)?;
        }
    }
    charts(&dir, &ext)?;
    Ok(())
}
