//! Real ProcTHOR houses, when `FERRET_PROCTHOR_DIR` points at the data: plans (PNG and SVG, with
//! the occupancy grid and a shortest path) and trajectory panels of the first houses of the
//! evaluation set.

mod common;

use std::path::PathBuf;

use common::{count_color, pixel, read_png, rgb};
use ferret_report::{
    PlanOptions, PlanPath, Rgb, TrajectoryOptions, TrajectoryPanel, draw_floor_plan,
    draw_trajectories, plan_colors, room_tint,
};
use ferret_world::distance::build;
use ferret_world::procthor::{AssetDatabase, LoadOptions, load_scenes};
use ferret_world::{GridParams, Place};

fn data_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("FERRET_PROCTHOR_DIR").map(PathBuf::from);
    if dir.is_none() {
        println!(
            "skipped: set FERRET_PROCTHOR_DIR to the directory of ProcTHOR house files to run"
        );
    }
    dir
}

#[test]
fn real_houses_are_drawn() {
    let Some(dir) = data_dir() else { return };
    let db = AssetDatabase::load(&dir.join("databases/asset-database.json")).ok();
    let opts = LoadOptions {
        shard: None,
        asset_db: db.as_ref(),
        range: "0..3".parse().unwrap(),
        skip_invalid: false,
        ..Default::default()
    };
    let scenes = load_scenes(&dir.join("multiroom-val150.jsonl.gz"), &opts)
        .unwrap()
        .scenes;
    assert_eq!(scenes.len(), 3);
    let out = tempfile::tempdir().unwrap();
    for (i, scene) in scenes.iter().enumerate() {
        let house = &scene.house;

        // Plain plan: rooms show their tints over most of their floor, containers their colour.
        let png = out.path().join(format!("plan{i}.png"));
        let plain = PlanOptions {
            container_labels: false,
            ..PlanOptions::default()
        };
        let layout = draw_floor_plan(house, &plain, &png).unwrap();
        let img = read_png(&png);
        assert_eq!((img.0, img.1), (layout.width, layout.height));
        assert!(
            layout.width <= 2000 && layout.height <= 2200,
            "{}×{}",
            layout.width,
            layout.height
        );
        let px2 = layout.px_per_m * layout.px_per_m;
        let mut by_type: std::collections::BTreeMap<&str, f64> = Default::default();
        for r in &house.rooms {
            *by_type.entry(r.room_type.as_str()).or_default() += r.floor.area() * px2;
        }
        for (t, area) in by_type {
            let seen = count_color(&img, rgb(room_tint(t))) as f64;
            assert!(
                seen > 0.4 * area,
                "house {i}: {t} shows {seen} of {area} px"
            );
        }
        let hits = house
            .containers
            .iter()
            .filter(|c| {
                pixel(&img, layout.to_pixel(c.footprint.center)) == rgb(plan_colors::CONTAINER)
            })
            .count();
        assert!(
            hits * 10 >= house.containers.len() * 8,
            "house {i}: {hits}/{} containers visible",
            house.containers.len()
        );
        assert!(count_color(&img, rgb(plan_colors::WALL)) > 1000);
        if !house.doors.is_empty() {
            assert!(count_color(&img, rgb(plan_colors::DOOR)) > 50);
        }

        // Plan with the grid, a shortest path and all names, as SVG.
        let (grid, d) = build(house, &GridParams::default()).unwrap();
        let goal = house.containers.len() - 1;
        let path = d.path(Place::Start, Place::Container(goal)).unwrap();
        let free = |p| grid.cell_of(p).is_some_and(|c| grid.is_free(c));
        let full = PlanOptions {
            occupancy: Some(&free),
            paths: vec![PlanPath {
                label: "shortest path".into(),
                color: Rgb::palette(3),
                points: path.clone(),
            }],
            ..PlanOptions::default()
        };
        let svg = out.path().join(format!("plan{i}.svg"));
        draw_floor_plan(house, &full, &svg).unwrap();
        let text = std::fs::read_to_string(&svg).unwrap();
        for c in &house.containers {
            assert!(
                text.contains(&c.object_type.words()),
                "house {i}: no label for {}",
                c.id
            );
        }
        let png = out.path().join(format!("full{i}.png"));
        let layout = draw_floor_plan(house, &full, &png).unwrap();
        let img = read_png(&png);
        assert!(
            count_color(&img, rgb(Rgb::palette(3))) as f64
                > 2.0 * layout.px_per_m * d.between(Place::Start, Place::Container(goal))
        );

        let panels = vec![TrajectoryPanel {
            title: "shortest".into(),
            cost_m: d.between(Place::Start, Place::Container(goal)),
            path,
            searched: vec![goal],
            goals: vec![goal],
            goal_labels: Vec::new(),
            destination: None,
            color: None,
            team_paths: Vec::new(),
            searched_by: Vec::new(),
        }];
        draw_trajectories(
            house,
            &panels,
            &TrajectoryOptions::default(),
            &out.path().join(format!("t{i}.png")),
        )
        .unwrap();
    }
}
