//! A small hand-built house shared by the tests: a kitchen and a living room side by side, a
//! door between them, five containers and two other pieces of furniture.

#![allow(dead_code)]

use std::path::Path;

use ferret_world::{
    Container, Door, Footprint, House, ObjectType, Obstacle, Point, Polygon, Pose, Room, RoomType,
    Wall,
};

pub fn rect_room(id: &str, room_type: &str, x0: f64, z0: f64, x1: f64, z1: f64) -> Room {
    Room {
        id: id.into(),
        room_type: RoomType::new(room_type),
        floor: Polygon::new(vec![
            Point::new(x0, z0),
            Point::new(x1, z0),
            Point::new(x1, z1),
            Point::new(x0, z1),
        ]),
    }
}

fn walls_of(room: &Room) -> Vec<Wall> {
    let v = &room.floor.vertices;
    (0..v.len())
        .map(|i| {
            let (a, b) = (v[i], v[(i + 1) % v.len()]);
            Wall {
                id: format!("wall|{}|{}|{}|{}|{}", room.id, a.x, a.z, b.x, b.z),
                room_id: room.id.clone(),
                start: a,
                end: b,
            }
        })
        .collect()
}

pub fn footprint(x: f64, z: f64, sx: f64, sz: f64, yaw: f64) -> Footprint {
    Footprint {
        center: Point::new(x, z),
        size_x: sx,
        size_z: sz,
        yaw_deg: yaw,
    }
}

fn container(id: &str, t: &str, room: usize, f: Footprint) -> Container {
    Container {
        id: id.into(),
        object_type: ObjectType::new(t),
        room: Some(room),
        position: f.center,
        footprint: f,
        access: None,
    }
}

/// Kitchen [0,4]×[0,4], living room [4,10]×[0,4], door at x = 4 from z = 1.5 to 2.5.
pub fn small_house() -> House {
    let kitchen = rect_room("room|0", "Kitchen", 0.0, 0.0, 4.0, 4.0);
    let living = rect_room("room|1", "LivingRoom", 4.0, 0.0, 10.0, 4.0);
    let mut walls = walls_of(&kitchen);
    walls.extend(walls_of(&living));
    let door_wall = walls
        .iter()
        .find(|w| w.start.x == 4.0 && w.end.x == 4.0)
        .map(|w| w.id.clone())
        .unwrap_or_default();
    House {
        name: "test house".into(),
        index: 0,
        rooms: vec![kitchen, living],
        walls,
        doors: vec![Door {
            id: "door|0|1".into(),
            rooms: ["room|0".into(), "room|1".into()],
            wall: door_wall,
            start: Point::new(4.0, 1.5),
            end: Point::new(4.0, 2.5),
        }],
        containers: vec![
            container("0|0|0", "Fridge", 0, footprint(0.45, 3.5, 0.8, 0.7, 0.0)),
            container(
                "0|0|1",
                "CounterTop",
                0,
                footprint(2.0, 0.35, 2.0, 0.6, 0.0),
            ),
            container("1|0|0", "Sofa", 1, footprint(7.0, 3.5, 2.0, 0.9, 180.0)),
            container("1|0|1", "TVStand", 1, footprint(7.0, 0.3, 1.4, 0.5, 0.0)),
            container("1|0|2", "Shelf", 1, footprint(9.4, 1.8, 1.0, 0.4, 60.0)),
        ],
        obstacles: vec![
            Obstacle {
                id: "0|1|0".into(),
                object_type: ObjectType::new("Chair"),
                room: Some(0),
                footprint: footprint(2.0, 2.2, 0.5, 0.5, 45.0),
            },
            Obstacle {
                id: "1|1|0".into(),
                object_type: ObjectType::new("FloorLamp"),
                room: Some(1),
                footprint: footprint(9.6, 3.6, 0.3, 0.3, 0.0),
            },
        ],
        start: Pose {
            position: Point::new(5.5, 2.0),
            yaw_deg: 90.0,
        },
        map: None,
    }
}

/// The PNG at `path` as (width, height, RGB bytes).
pub fn read_png(path: &Path) -> (u32, u32, Vec<u8>) {
    let file = std::fs::File::open(path).expect("png written");
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info().expect("png header");
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).expect("png frame");
    let channels = info.color_type.samples();
    let rgb = buf[..info.buffer_size()]
        .chunks(channels)
        .flat_map(|px| [px[0], px[1], px[2]])
        .collect();
    (info.width, info.height, rgb)
}

/// The colour of pixel `(x, y)`.
pub fn pixel(img: &(u32, u32, Vec<u8>), (x, y): (f64, f64)) -> [u8; 3] {
    let (w, _, data) = img;
    let i = (y.floor() as usize * *w as usize + x.floor() as usize) * 3;
    [data[i], data[i + 1], data[i + 2]]
}

/// How many pixels have exactly this colour.
pub fn count_color(img: &(u32, u32, Vec<u8>), c: [u8; 3]) -> usize {
    img.2.chunks(3).filter(|p| p == &c).count()
}

pub fn rgb(c: ferret_report::Rgb) -> [u8; 3] {
    [c.r, c.g, c.b]
}
