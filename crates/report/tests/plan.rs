//! Floor plans and trajectory panels of a small hand-built house: sizes, colours at known places,
//! text in SVG, and errors on bad input.

mod common;

use common::{count_color, pixel, read_png, rgb, small_house};
use ferret_report::{
    GridImage, PlanOptions, PlanPath, ReportError, Rgb, TrajectoryOptions, TrajectoryPanel,
    draw_floor_plan, draw_trajectories, plan_colors, room_tint,
};
use ferret_world::Point;

fn path_to_fridge() -> Vec<Point> {
    vec![
        Point::new(5.5, 2.0),
        Point::new(8.0, 2.0),
        Point::new(8.0, 2.6),
        Point::new(4.0, 2.0),
        Point::new(1.0, 3.0),
    ]
}

#[test]
fn floor_plan_png_has_tints_walls_doors_furniture_and_path() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("plan.png");
    let house = small_house();
    let color = Rgb::palette(3);
    let opts = PlanOptions {
        paths: vec![PlanPath {
            label: "to the fridge".into(),
            color,
            points: path_to_fridge(),
        }],
        container_labels: false,
        ..PlanOptions::default()
    };
    let layout = draw_floor_plan(&house, &opts, &out).unwrap();
    let img = read_png(&out);
    assert_eq!((img.0, img.1), (layout.width, layout.height));
    // Default scale for a 10.9 m wide plan: raised so the long side is 640 px.
    assert!(
        layout.px_per_m >= 40.0 && layout.px_per_m <= 80.0,
        "{}",
        layout.px_per_m
    );
    assert!(layout.plot_width >= 640.0);

    // Equal aspect: a metre is as long along z as along x.
    let o = layout.to_pixel(Point::new(0.0, 0.0));
    let ex = layout.to_pixel(Point::new(1.0, 0.0));
    let ez = layout.to_pixel(Point::new(0.0, 1.0));
    assert!(((ex.0 - o.0) - (o.1 - ez.1)).abs() < 1e-9);

    let at = |x: f64, z: f64| pixel(&img, layout.to_pixel(Point::new(x, z)));
    // Room interiors, away from furniture, labels and the path.
    assert_eq!(at(0.6, 1.4), rgb(room_tint("Kitchen")));
    assert_eq!(at(9.4, 0.6), rgb(room_tint("LivingRoom")));
    assert_ne!(room_tint("Kitchen"), room_tint("LivingRoom"));
    // Walls: the kitchen's west wall and the shared wall away from the door.
    assert_eq!(at(0.0, 2.0), rgb(plan_colors::WALL));
    assert_eq!(at(4.0, 0.8), rgb(plan_colors::WALL));
    // The door opening.
    assert_eq!(at(4.0, 1.7), rgb(plan_colors::DOOR));
    // Furniture: the fridge (container) and the chair (other furniture).
    assert_eq!(at(0.45, 3.5), rgb(plan_colors::CONTAINER));
    assert_eq!(at(2.0, 2.2), rgb(plan_colors::OBSTACLE));
    // The path, on its first straight stretch.
    assert_eq!(at(6.8, 2.0), rgb(color));
    // The start marker.
    assert_eq!(at(5.5, 2.0), rgb(plan_colors::START));
    // Nothing is drawn outside the house but axes and text: the far corner is background.
    assert_eq!(
        pixel(&img, (layout.width as f64 - 3.0, 3.0)),
        [255, 255, 255]
    );
}

#[test]
fn rotated_footprints_are_drawn_rotated() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("plan.png");
    let house = small_house();
    let opts = PlanOptions {
        container_labels: false,
        ..PlanOptions::default()
    };
    let layout = draw_floor_plan(&house, &opts, &out).unwrap();
    let img = read_png(&out);
    // The shelf (1.0 × 0.4 m, yaw 60°) reaches 0.4 m along its own x axis, which Unity's yaw turns
    // towards −z: (cos 60°, −sin 60°)·0.4 from its centre. Unrotated, that point would be outside.
    let shelf = &house.containers[4].footprint;
    let (s, c) = 60f64.to_radians().sin_cos();
    let inside = Point::new(shelf.center.x + 0.4 * c, shelf.center.z - 0.4 * s);
    let outside = Point::new(shelf.center.x + 0.4, shelf.center.z);
    assert!(shelf.contains(inside) && !shelf.contains(outside));
    assert_eq!(
        pixel(&img, layout.to_pixel(inside)),
        rgb(plan_colors::CONTAINER)
    );
    assert_eq!(
        pixel(&img, layout.to_pixel(outside)),
        rgb(room_tint("LivingRoom"))
    );
}

#[test]
fn floor_plan_svg_names_rooms_and_every_container() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("plan.svg");
    let house = small_house();
    draw_floor_plan(&house, &PlanOptions::default(), &out).unwrap();
    let svg = std::fs::read_to_string(&out).unwrap();
    assert!(svg.starts_with("<svg"), "{}", &svg[..40.min(svg.len())]);
    for name in [
        "fridge 0|0|0",
        "counter top 0|0|1",
        "sofa 1|0|0",
        "tv stand 1|0|1",
        "shelf 1|0|2",
    ] {
        assert!(
            svg.contains(&format!(">\n{name}\n<")) || svg.contains(name),
            "missing {name}"
        );
    }
    for room in ["Kitchen", "Living room", "test house", "x (m)", "z (m)"] {
        assert!(svg.contains(room), "missing {room}");
    }
}

#[test]
fn container_labels_do_not_overlap_each_other() {
    // Ten containers in a row against one wall: their labels must all find separate places.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("crowded.svg");
    let mut house = small_house();
    let template = house.containers[1].clone();
    house.containers = (0..10)
        .map(|i| {
            let mut c = template.clone();
            c.id = format!("0|2|{i}");
            c.footprint = common::footprint(0.3 + 0.38 * i as f64, 0.3, 0.35, 0.5, 0.0);
            c.position = c.footprint.center;
            c
        })
        .collect();
    draw_floor_plan(&house, &PlanOptions::default(), &out).unwrap();
    let svg = std::fs::read_to_string(&out).unwrap();
    // Each label is a <text> element centred on its x, y.
    let texts: Vec<&str> = svg.split("<text").skip(1).collect();
    let label_positions: Vec<(f64, f64)> = texts
        .iter()
        .filter(|t| t.contains("counter top 0|2|"))
        .filter_map(|t| {
            let get = |name: &str| {
                t.split(&format!("{name}=\""))
                    .nth(1)?
                    .split('"')
                    .next()?
                    .parse::<f64>()
                    .ok()
            };
            Some((get("x")?, get("y")?))
        })
        .collect();
    assert_eq!(label_positions.len(), 10);
    for (i, a) in label_positions.iter().enumerate() {
        for b in &label_positions[i + 1..] {
            // Labels are about 90 px wide and 13 px tall (padding included).
            let apart = (a.0 - b.0).abs() >= 80.0 || (a.1 - b.1).abs() >= 12.0;
            assert!(apart, "labels at {a:?} and {b:?} overlap");
        }
    }
}

#[test]
fn occupancy_overlay_shades_only_occupied_floor() {
    let dir = tempfile::tempdir().unwrap();
    let house = small_house();
    // A 0.5 m grid over the house where the kitchen's west half (x < 2) is occupied.
    let (w, h) = (20, 8);
    let free = (0..h).flat_map(|_| (0..w).map(|i| i >= 4)).collect();
    let grid = GridImage {
        origin: Point::new(0.0, 0.0),
        resolution: 0.5,
        width: w,
        height: h,
        free,
    };
    let is_free = |p: Point| grid.is_free(p);
    let opts = PlanOptions {
        occupancy: Some(&is_free),
        container_labels: false,
        ..PlanOptions::default()
    };
    let out = dir.path().join("occ.png");
    let layout = draw_floor_plan(&house, &opts, &out).unwrap();
    let img = read_png(&out);
    let shaded = pixel(&img, layout.to_pixel(Point::new(0.6, 1.4)));
    let tint = rgb(room_tint("Kitchen"));
    assert_ne!(shaded, tint);
    // Translucent: darker than the tint, towards the overlay colour.
    assert!(
        shaded.iter().map(|&c| c as u32).sum::<u32>() < tint.iter().map(|&c| c as u32).sum::<u32>()
    );
    assert_eq!(pixel(&img, layout.to_pixel(Point::new(3.0, 1.4))), tint);
    assert_eq!(
        pixel(&img, layout.to_pixel(Point::new(9.4, 0.6))),
        rgb(room_tint("LivingRoom"))
    );
    // Outside the house nothing is shaded even though the grid calls it occupied.
    assert_eq!(
        pixel(&img, layout.to_pixel(Point::new(-0.3, 2.0))),
        [255, 255, 255]
    );

    // The SVG overlay is made of merged runs, not one rectangle per pixel.
    let svg_out = dir.path().join("occ.svg");
    draw_floor_plan(&house, &opts, &svg_out).unwrap();
    let rects = std::fs::read_to_string(&svg_out)
        .unwrap()
        .matches("<rect")
        .count();
    assert!(rects < 2000, "{rects} rectangles");
}

fn panels() -> Vec<TrajectoryPanel> {
    vec![
        TrajectoryPanel {
            title: "optimistic+greedy".into(),
            cost_m: 17.25,
            path: vec![
                Point::new(5.5, 2.0),
                Point::new(7.0, 0.9),
                Point::new(7.0, 2.9),
                Point::new(4.0, 2.0),
                Point::new(0.9, 3.4),
            ],
            searched: vec![3, 2, 0],
            goals: vec![0],
            goal_labels: Vec::new(),
            destination: None,
            color: None,
            team_paths: Vec::new(),
            searched_by: Vec::new(),
        },
        TrajectoryPanel {
            title: "llm+model/p-context-a/gpt-5-mini".into(),
            cost_m: 5.31,
            path: vec![
                Point::new(5.5, 2.0),
                Point::new(4.0, 2.0),
                Point::new(0.9, 3.4),
            ],
            searched: vec![0],
            goals: vec![0],
            goal_labels: Vec::new(),
            destination: None,
            color: None,
            team_paths: Vec::new(),
            searched_by: Vec::new(),
        },
        TrajectoryPanel {
            title: "oracle".into(),
            cost_m: 5.31,
            path: vec![
                Point::new(5.5, 2.0),
                Point::new(4.0, 2.0),
                Point::new(0.9, 3.4),
            ],
            searched: vec![0],
            goals: vec![0],
            goal_labels: Vec::new(),
            destination: None,
            color: Some(Rgb::new(10, 20, 30)),
            team_paths: Vec::new(),
            searched_by: Vec::new(),
        },
    ]
}

#[test]
fn trajectory_panels_png_and_svg() {
    let dir = tempfile::tempdir().unwrap();
    let house = small_house();
    let opts = TrajectoryOptions {
        title: Some("Target: apple".into()),
        ..TrajectoryOptions::default()
    };
    let png = dir.path().join("traj.png");
    draw_trajectories(&house, &panels(), &opts, &png).unwrap();
    let img = read_png(&png);
    // Three panels side by side: wider than tall.
    assert!(img.0 > 2 * img.1, "{}×{}", img.0, img.1);
    // Each panel's path colour appears: the first two from the palette, the third its own.
    for c in [rgb(Rgb::palette(0)), rgb(Rgb::palette(1)), [10, 20, 30]] {
        assert!(count_color(&img, c) > 100, "colour {c:?} missing");
    }
    // Goal containers are painted in the goal colour in every panel.
    assert!(count_color(&img, rgb(plan_colors::GOAL)) > 3 * 100);

    let svg = dir.path().join("traj.svg");
    draw_trajectories(&house, &panels(), &opts, &svg).unwrap();
    let text = std::fs::read_to_string(&svg).unwrap();
    for s in [
        "Target: apple",
        "17.2 m",
        "5.3 m",
        "optimistic+greedy",
        "goal: fridge",
        "searched: 1 tv stand",
    ] {
        assert!(text.contains(s), "missing {s}");
    }
}

#[test]
fn bad_input_gives_typed_errors() {
    let dir = tempfile::tempdir().unwrap();
    let house = small_house();
    let err = draw_floor_plan(
        &house,
        &PlanOptions::default(),
        &dir.path().join("plan.jpg"),
    )
    .unwrap_err();
    assert!(
        matches!(err, ReportError::UnsupportedFormat { .. }),
        "{err}"
    );

    let mut empty = house.clone();
    empty.rooms.clear();
    let err =
        draw_floor_plan(&empty, &PlanOptions::default(), &dir.path().join("p.png")).unwrap_err();
    assert!(matches!(err, ReportError::InvalidInput { .. }), "{err}");

    let mut nan = house.clone();
    nan.containers[0].footprint.size_x = f64::NAN;
    let err =
        draw_floor_plan(&nan, &PlanOptions::default(), &dir.path().join("p.png")).unwrap_err();
    assert!(err.to_string().contains("0|0|0"), "{err}");

    let opts = PlanOptions {
        paths: vec![PlanPath {
            label: "p".into(),
            color: Rgb::palette(0),
            points: vec![Point::new(f64::INFINITY, 0.0)],
        }],
        ..PlanOptions::default()
    };
    assert!(matches!(
        draw_floor_plan(&house, &opts, &dir.path().join("p.png")),
        Err(ReportError::InvalidInput { .. })
    ));

    let mut bad = panels();
    bad[0].searched.push(99);
    let err = draw_trajectories(
        &house,
        &bad,
        &TrajectoryOptions::default(),
        &dir.path().join("t.png"),
    )
    .unwrap_err();
    assert!(err.to_string().contains("99"), "{err}");
    let err = draw_trajectories(
        &house,
        &[],
        &TrajectoryOptions::default(),
        &dir.path().join("t.png"),
    )
    .unwrap_err();
    assert!(matches!(err, ReportError::InvalidInput { .. }));

    // A directory that does not exist: a drawing error naming the file, not a panic.
    let err = draw_floor_plan(
        &house,
        &PlanOptions::default(),
        &dir.path().join("no/such/dir/p.png"),
    )
    .unwrap_err();
    assert!(matches!(err, ReportError::Draw { .. }), "{err}");
    let err = draw_floor_plan(
        &house,
        &PlanOptions::default(),
        &dir.path().join("no/such/dir/p.svg"),
    )
    .unwrap_err();
    assert!(matches!(err, ReportError::Draw { .. }), "{err}");
}
