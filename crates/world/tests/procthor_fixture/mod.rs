//! Small hand-written ProcTHOR houses shared by the `procthor_*` tests.
#![allow(dead_code)]

use serde_json::{Value, json};

fn v(x: f64, z: f64) -> Value {
    json!({"x": x, "y": 0.0, "z": z})
}

fn wall(id: &str, room: &str, a: (f64, f64), b: (f64, f64)) -> Value {
    json!({
        "id": id, "roomId": room,
        "polygon": [v(a.0, a.1), v(b.0, b.1),
                    {"x": a.0, "y": 2.5, "z": a.1}, {"x": b.0, "y": 2.5, "z": b.1}]
    })
}

/// Two rooms side by side: a kitchen `room|1` on [0,4]×[0,3] and a living room `room|2` on
/// [4,8]×[0,3], one door between them in the wall x = 4. The kitchen's copy of that wall runs
/// from (4,3) down to (4,0), so its first endpoint is NOT its min corner: a hole at 0.5..1.5 m
/// along it spans z = 2.5 down to 1.5. Ids in the `4|0|0` style, no `objectType` fields except
/// on one object.
pub fn house_a() -> Value {
    json!({
        "rooms": [
            {"id": "room|1", "roomType": "Kitchen",
             "floorPolygon": [v(0.0, 0.0), v(0.0, 3.0), v(4.0, 3.0), v(4.0, 0.0)]},
            {"id": "room|2", "roomType": "LivingRoom",
             "floorPolygon": [v(4.0, 0.0), v(4.0, 3.0), v(8.0, 3.0), v(8.0, 0.0)]}
        ],
        "walls": [
            wall("wall|1|0.00|0.00|4.00|0.00", "room|1", (0.0, 0.0), (4.0, 0.0)),
            wall("wall|1|4.00|0.00|4.00|3.00", "room|1", (4.0, 3.0), (4.0, 0.0)),
            wall("wall|2|4.00|0.00|4.00|3.00", "room|2", (4.0, 0.0), (4.0, 3.0)),
            wall("wall|2|4.00|3.00|8.00|3.00", "room|2", (4.0, 3.0), (8.0, 3.0))
        ],
        "doors": [
            {"id": "door|1|2", "room0": "room|1", "room1": "room|2",
             "wall0": "wall|1|4.00|0.00|4.00|3.00", "wall1": "wall|2|4.00|0.00|4.00|3.00",
             "assetId": "Doorway_1",
             "holePolygon": [{"x": 0.5, "y": 0.0, "z": 0.0}, {"x": 1.5, "y": 2.1, "z": 0.0}]}
        ],
        "windows": [
            {"id": "window|1|0", "room0": "room|1", "room1": "room|1",
             "wall0": "wall|1|0.00|0.00|4.00|0.00", "wall1": "wall|exterior|0.00|0.00|4.00|0.00",
             "assetId": "Window_Fixed_36x48",
             "holePolygon": [{"x": 1.0, "y": 1.0, "z": 0.0}, {"x": 2.0, "y": 2.0, "z": 0.0}]},
            {"id": "window|2|0", "room0": "room|2", "room1": "room|2",
             "wall0": "wall|2|no|such|wall", "wall1": "",
             "holePolygon": [{"x": 1.0, "y": 1.0, "z": 0.0}, {"x": 2.0, "y": 2.0, "z": 0.0}]}
        ],
        "objects": [
            {"id": "1|0", "assetId": "Fridge_1", "kinematic": true,
             "position": {"x": 0.5, "y": 0.9, "z": 0.5}, "rotation": {"x": 0, "y": 90, "z": 0},
             "children": [
                {"id": "small|1|0", "assetId": "Egg_3",
                 "position": {"x": 0.5, "y": 1.0, "z": 0.5}, "rotation": {"x": 0, "y": 0, "z": 0}},
                {"id": "small|1|1", "assetId": "Apple_2",
                 "position": {"x": 0.5, "y": 1.2, "z": 0.5}, "rotation": {"x": 0, "y": 0, "z": 0}}
             ]},
            {"id": "1|1|0", "assetId": "Countertop_I_6x2",
             "position": {"x": 2.0, "y": 0.45, "z": 0.4}, "rotation": {"x": 0, "y": 0, "z": 0},
             "children": [
                {"id": "small|1|2", "assetId": "Microwave_3",
                 "position": {"x": 2.0, "y": 1.0, "z": 0.4}, "rotation": {"x": 0, "y": 0, "z": 0}},
                {"id": "small|1|3", "assetId": "Cellphone_2",
                 "position": {"x": 2.5, "y": 1.0, "z": 0.4}, "rotation": {"x": 0, "y": 0, "z": 0}}
             ]},
            {"id": "1|2", "assetId": "Chair_204_1",
             "position": {"x": 2.0, "y": 0.4, "z": 1.2}, "rotation": {"x": 0, "y": 180, "z": 0}},
            {"id": "1|3", "assetId": "Wall_Decor_Painting_2",
             "position": {"x": 0.02, "y": 1.8, "z": 2.0}, "rotation": {"x": 0, "y": 90, "z": 0}},
            {"id": "2|0", "assetId": "RoboTHOR_sofa_kramfors",
             "position": {"x": 6.0, "y": 0.4, "z": 2.5}, "rotation": {"x": 0, "y": 180, "z": 0},
             "children": [
                {"id": "small|2|4", "assetId": "Remote_1",
                 "position": {"x": 6.0, "y": 0.6, "z": 2.5}, "rotation": {"x": 0, "y": 0, "z": 0}}
             ]},
            {"id": "2|1", "assetId": "Mystery_1", "objectType": "Dresser",
             "position": {"x": 7.5, "y": 0.4, "z": 0.3}, "rotation": {"x": 0, "y": 0, "z": 0},
             "children": [
                {"id": "small|2|5", "assetId": "Mystery_2", "objectType": "Book",
                 "position": {"x": 7.5, "y": 0.9, "z": 0.3}, "rotation": {"x": 0, "y": 0, "z": 0}}
             ]},
            {"id": "2|2", "assetId": "Floor_Lamp_3",
             "position": {"x": 7.6, "y": 1.0, "z": 2.6}, "rotation": {"x": 0, "y": 0, "z": 0}}
        ],
        "metadata": {
            "agent": {"position": {"x": 2.0, "y": 0.95, "z": 1.5},
                      "rotation": {"x": 0, "y": 90, "z": 0}, "horizon": 30, "standing": true},
            "schema": "1.0.0"
        }
    })
}

/// The same house with ids in the `Fridge|2|0` style (room index second), `objectType` on every
/// object, and a sofa whose id says room 1 but which stands in room 2.
pub fn house_b() -> Value {
    let mut h = house_a();
    let ids = [
        ("1|0", "Fridge|1|0", "Fridge"),
        ("1|1|0", "CounterTop|1|1", "CounterTop"),
        ("1|2", "Chair|1|2", "Chair"),
        ("1|3", "Painting|1|3", "Painting"),
        ("2|0", "Sofa|1|0", "Sofa"),
        ("2|1", "Dresser|2|1", "Dresser"),
        ("2|2", "FloorLamp|2|2", "FloorLamp"),
    ];
    for o in h["objects"].as_array_mut().expect("objects") {
        let (_, new, ty) = ids
            .iter()
            .find(|(old, _, _)| o["id"] == *old)
            .expect("known id");
        o["id"] = json!(new);
        o["objectType"] = json!(ty);
    }
    h
}

/// A small asset database in the generator's format.
pub const ASSET_DB: &str = r#"{
    "Fridge": [{"assetId": "Fridge_1", "objectType": "Fridge",
                "boundingBox": {"x": 0.9, "y": 1.8, "z": 0.7}, "secondaryProperties": ["Receptacle"]}],
    "Safe": [{"assetId": "Mystery_1", "objectType": "Safe",
              "boundingBox": {"x": 0.4, "y": 0.5, "z": 0.45}, "secondaryProperties": ["Receptacle"]}],
    "Chair": [{"assetId": "Chair_204_1", "objectType": "Chair",
               "boundingBox": {"x": 0.45, "y": 0.9, "z": 0.5}}]
}"#;

/// A house written the ProcTHOR-10k way: types only in the id prefixes (`Fridge|1|0`,
/// `Egg|surface|1|3`), no `objectType` fields, no asset known to any database. Besides the
/// furniture of [`house_a`] it has a box (an ignored type) holding a cup, a chair-typed child
/// on the sofa (a child whose type is also a top-level type), and a grandchild under the remote.
pub fn house_10k() -> Value {
    let mut h = house_a();
    let renames = [
        ("1|0", "Fridge|1|0"),
        ("small|1|0", "Egg|surface|1|10"),
        ("small|1|1", "Apple|surface|1|11"),
        ("1|1|0", "CounterTop|1|1"),
        ("small|1|2", "Microwave|surface|1|12"),
        ("small|1|3", "CellPhone|surface|1|13"),
        ("1|2", "Chair|1|2"),
        ("1|3", "Painting|1|3"),
        ("2|0", "Sofa|2|0"),
        ("small|2|4", "RemoteControl|surface|2|14"),
        ("2|1", "Dresser|2|1"),
        ("small|2|5", "Book|surface|2|15"),
        ("2|2", "FloorLamp|2|2"),
    ];
    fn rename(o: &mut Value, renames: &[(&str, &str)]) {
        if let Some((_, new)) = renames.iter().find(|(old, _)| o["id"] == *old) {
            o["id"] = json!(new);
        }
        if let Some(m) = o.as_object_mut() {
            m.remove("objectType");
            m.insert("assetId".into(), json!("Unlisted_1"));
        }
        if let Some(children) = o.get_mut("children").and_then(Value::as_array_mut) {
            for c in children {
                rename(c, renames);
            }
        }
    }
    let objects = h["objects"].as_array_mut().expect("objects");
    for o in objects.iter_mut() {
        rename(o, &renames);
    }
    let child = |id: &str, x: f64, z: f64| {
        json!({"id": id, "assetId": "Unlisted_1",
               "position": {"x": x, "y": 0.8, "z": z}, "rotation": {"x": 0, "y": 0, "z": 0}})
    };
    let sofa = objects
        .iter_mut()
        .find(|o| o["id"] == "Sofa|2|0")
        .expect("sofa");
    sofa["children"]
        .as_array_mut()
        .expect("children")
        .push(child("Chair|surface|2|16", 6.2, 2.5));
    sofa["children"][0]["children"] = json!([child("Pen|surface|2|17", 6.0, 2.5)]);
    let mut bx = child("Box|2|3", 3.0, 2.5);
    bx["position"]["y"] = json!(0.2);
    bx["children"] = json!([child("Cup|surface|1|18", 3.0, 2.5)]);
    objects.push(bx);
    h
}
