//! Object types without an asset database: our own assetId → type mapping, which types are
//! containers, which are searchable contents, and per-type footprint sizes.
//!
//! The mapping is written by hand from the naming patterns of ProcTHOR/AI2-THOR assets
//! (`Fridge_16`, `RoboTHOR_sofa_kramfors`, `Countertop_C_10x8`, `bin_8`): the assetId is split
//! into lower-case words, numbers and variant marks are dropped, and ordered keyword rules pick
//! the type. It holds no list of assetIds; `tests/procthor_data.rs` measures its agreement with
//! the generator's asset database.

use crate::house::ObjectType;

/// How a rule matches the normalised assetId.
#[derive(Clone, Copy)]
enum Match {
    /// The joined words start with this.
    Prefix(&'static str),
    /// The joined words contain this anywhere.
    Contains(&'static str),
    /// The first word is exactly this (for short names such as `pan`, which would otherwise
    /// match `pantry` or `panel`).
    First(&'static str),
    /// The joined words are exactly this.
    Exact(&'static str),
}

/// Ordered rules: the first match wins, so more specific names come before the words they
/// contain (`desklamp` before `desk`, `armchair` before `chair`, statues and faucets before
/// whatever they are statues or faucets of).
const RULES: &[(Match, &str)] = {
    use Match::{Contains, Exact, First, Prefix};
    &[
        // Decorative and fixture variants named after other things.
        (Contains("statue"), "Statue"),
        (Contains("faucet"), "Faucet"),
        (Contains("daybed"), "Bed"),
        (Prefix("officechair"), "Chair"),
        (Prefix("handtowelholder"), "HandTowelHolder"),
        (Contains("towelholder"), "TowelHolder"),
        (Prefix("toiletpaperhanger"), "ToiletPaperHanger"),
        (Prefix("toiletpaper"), "ToiletPaper"),
        (Prefix("toilet"), "Toilet"),
        (Prefix("alarmclock"), "AlarmClock"),
        (Prefix("aluminumfoil"), "AluminumFoil"),
        (Prefix("apple"), "Apple"),
        (Prefix("armchair"), "ArmChair"),
        (Prefix("baseballbat"), "BaseballBat"),
        (Prefix("basketball"), "BasketBall"),
        (Prefix("bathtowel"), "Towel"),
        (Prefix("handtowel"), "HandTowel"),
        (Prefix("towel"), "Towel"),
        (Prefix("bathtubbasin"), "BathtubBasin"),
        (Prefix("bathtub"), "Bathtub"),
        (Prefix("dogbed"), "DogBed"),
        (First("bed"), "Bed"),
        (Prefix("blinds"), "Blinds"),
        (Prefix("book"), "Book"),
        (Prefix("boot"), "Boots"),
        (Prefix("soapbottle"), "SoapBottle"),
        (Prefix("spraybottle"), "SprayBottle"),
        (Prefix("winebottle"), "WineBottle"),
        (Prefix("bottle"), "Bottle"),
        (Prefix("bowl"), "Bowl"),
        (Prefix("tissuebox"), "TissueBox"),
        (Prefix("decorativebox"), "Box"),
        (First("box"), "Box"),
        (Prefix("bread"), "Bread"),
        (Prefix("butterknife"), "ButterKnife"),
        (Prefix("knife"), "Knife"),
        (Exact("cd"), "CD"),
        (Prefix("candle"), "Candle"),
        (Prefix("cart"), "Cart"),
        (Prefix("cellphone"), "CellPhone"),
        (Prefix("chair"), "Chair"),
        (Prefix("clothesdryer"), "ClothesDryer"),
        (Prefix("cloth"), "Cloth"),
        (Prefix("coffeemachine"), "CoffeeMachine"),
        (Prefix("coffeetable"), "CoffeeTable"),
        (Prefix("countertop"), "CounterTop"),
        (Prefix("creditcard"), "CreditCard"),
        (First("cup"), "Cup"),
        (Prefix("desklamp"), "DeskLamp"),
        (Prefix("desktop"), "Desktop"),
        (Prefix("desk"), "Desk"),
        (Prefix("diningtable"), "DiningTable"),
        (Prefix("dishsponge"), "DishSponge"),
        (Prefix("doorframe"), "Doorframe"),
        (Prefix("doorway"), "Doorway"),
        (Prefix("dresser"), "Dresser"),
        (Prefix("dumbbell"), "Dumbbell"),
        (First("egg"), "Egg"),
        (Prefix("floorlamp"), "FloorLamp"),
        (Prefix("footstool"), "Footstool"),
        (Prefix("fork"), "Fork"),
        (Prefix("fridge"), "Fridge"),
        (Prefix("refrigerator"), "Fridge"),
        (Prefix("garbagebag"), "GarbageBag"),
        (Prefix("garbage"), "GarbageCan"),
        (Prefix("trash"), "GarbageCan"),
        (First("bin"), "GarbageCan"),
        (Prefix("houseplant"), "HousePlant"),
        (Prefix("kettle"), "Kettle"),
        (Prefix("keychain"), "KeyChain"),
        (Prefix("ladle"), "Ladle"),
        (Prefix("laptop"), "Laptop"),
        (Prefix("laundryhamper"), "LaundryHamper"),
        (Prefix("lettuce"), "Lettuce"),
        (Prefix("lightswitch"), "LightSwitch"),
        (Prefix("microwave"), "Microwave"),
        (First("mug"), "Mug"),
        (Prefix("newspaper"), "Newspaper"),
        (Prefix("ottoman"), "Ottoman"),
        (Prefix("walldecor"), "Painting"),
        (Prefix("painting"), "Painting"),
        (First("pan"), "Pan"),
        (Prefix("papertowel"), "PaperTowelRoll"),
        (Prefix("pencil"), "Pencil"),
        (First("pen"), "Pen"),
        (Prefix("pillow"), "Pillow"),
        (Prefix("plate"), "Plate"),
        (Prefix("plunger"), "Plunger"),
        (Prefix("potato"), "Potato"),
        (First("pot"), "Pot"),
        (Prefix("remote"), "RemoteControl"),
        (Prefix("roomdecor"), "RoomDecor"),
        (First("safe"), "Safe"),
        (Prefix("scrubbrush"), "ScrubBrush"),
        (Prefix("shelvingunit"), "ShelvingUnit"),
        (Prefix("showercurtain"), "ShowerCurtain"),
        (Prefix("showerhead"), "ShowerHead"),
        (Prefix("sidetable"), "SideTable"),
        (Prefix("sink"), "Sink"),
        (Prefix("soapbar"), "SoapBar"),
        (Prefix("sofa"), "Sofa"),
        (Prefix("couch"), "Sofa"),
        (Prefix("spatula"), "Spatula"),
        (Prefix("spoon"), "Spoon"),
        (Prefix("stool"), "Stool"),
        (Prefix("tvstand"), "TVStand"),
        (Prefix("tabletopdecor"), "TableTopDecor"),
        (Prefix("teddybear"), "TeddyBear"),
        (Prefix("television"), "Television"),
        (Prefix("tennisrac"), "TennisRacket"),
        (Prefix("toaster"), "Toaster"),
        (Prefix("tomato"), "Tomato"),
        (Prefix("vacuumcleaner"), "VacuumCleaner"),
        (Prefix("vase"), "Vase"),
        (Prefix("washingmachine"), "WashingMachine"),
        (Prefix("watch"), "Watch"),
        (Prefix("wateringcan"), "WateringCan"),
        (Prefix("window"), "Window"),
    ]
};

/// Splits an assetId into lower-case words without numbers or variant marks:
/// `RoboTHOR_sofa_kramfors` → `[sofa, kramfors]`, `Countertop_C_10x8` → `[countertop, c]`,
/// `Wall_Decor_Photo_2V` → `[wall, decor, photo]`, `Hand_Towel_Holder1` → `[hand, towel, holder]`.
fn words(asset_id: &str) -> Vec<String> {
    let lower = asset_id.to_ascii_lowercase();
    let body = lower.strip_prefix("robothor_").unwrap_or(&lower);
    body.split(|c: char| !c.is_ascii_alphanumeric())
        // Sizes (`10x8`), indices (`2`) and indexed variants (`1v`) start with a digit.
        .filter(|w| w.chars().next().is_some_and(|c| c.is_ascii_alphabetic()))
        .map(|w| w.trim_end_matches(|c: char| c.is_ascii_digit()))
        // `_v` marks a RoboTHOR variant, not a word of the name.
        .filter(|w| !w.is_empty() && *w != "v")
        .map(str::to_owned)
        .collect()
}

/// The object type of a ProcTHOR/AI2-THOR asset from its assetId alone, by naming rules of our
/// own; `None` when no rule matches.
///
/// ```
/// use ferret_world::procthor::types::object_type_for_asset;
/// assert_eq!(object_type_for_asset("RoboTHOR_sofa_kramfors").unwrap().as_str(), "Sofa");
/// assert_eq!(object_type_for_asset("Countertop_C_10x8").unwrap().as_str(), "CounterTop");
/// assert_eq!(object_type_for_asset("bin_8").unwrap().as_str(), "GarbageCan");
/// assert!(object_type_for_asset("Spaceship_3").is_none());
/// ```
pub fn object_type_for_asset(asset_id: &str) -> Option<ObjectType> {
    let words = words(asset_id);
    let first = words.first()?;
    // RoboTHOR keeps salt and pepper in one family, `salt_pepper_shaker_<brand>_<which>`: the
    // last word says which shaker it is.
    if words.iter().any(|w| w == "shaker") {
        return match words.last().map(String::as_str) {
            Some("pepper") => Some(ObjectType::new("PepperShaker")),
            Some("salt") => Some(ObjectType::new("SaltShaker")),
            _ if first == "pepper" => Some(ObjectType::new("PepperShaker")),
            _ => Some(ObjectType::new("SaltShaker")),
        };
    }
    let joined = words.concat();
    RULES
        .iter()
        .find(|(m, _)| match *m {
            Match::Prefix(p) => joined.starts_with(p),
            Match::Contains(p) => joined.contains(p),
            Match::First(p) => first == p,
            Match::Exact(p) => joined == p,
        })
        .map(|(_, t)| ObjectType::new(*t))
}

/// Receptacle object types of AI2-THOR (its object-type documentation, "Receptacle" column), the
/// types ProcTHOR places small objects in or on, minus seating: `Chair`, `Stool` and `Footstool`
/// rarely hold anything and a dining table brings about five chairs, which would swamp the
/// search with near-empty containers. With this list multiroom-val150 has about 22 containers per
/// house, as the paper's setting expects.
const CONTAINER_TYPES: &[&str] = &[
    "ArmChair",
    "Bathtub",
    "BathtubBasin",
    "Bed",
    "Bowl",
    "Box",
    "Cabinet",
    "Cart",
    "ClothesDryer",
    "CoffeeMachine",
    "CoffeeTable",
    "CounterTop",
    "Cup",
    "Desk",
    "DiningTable",
    "DogBed",
    "Drawer",
    "Dresser",
    "Fridge",
    "GarbageCan",
    "HandTowelHolder",
    "LaundryHamper",
    "Microwave",
    "Mug",
    "Ottoman",
    "Pan",
    "Plate",
    "Pot",
    "Safe",
    "Shelf",
    "ShelvingUnit",
    "SideTable",
    "Sink",
    "SinkBasin",
    "Sofa",
    "StoveBurner",
    "TVStand",
    "Toaster",
    "Toilet",
    "ToiletPaperHanger",
    "TowelHolder",
    "WashingMachine",
];

/// True when a top-level object of this type is a container the robot searches.
pub fn is_container_type(t: &ObjectType) -> bool {
    CONTAINER_TYPES.contains(&t.as_str())
}

/// Pickupable small objects of AI2-THOR (its object-type documentation, "Pickupable" column):
/// the things one searches for. Children that are furniture or fixtures in their own right
/// (a television on a stand, a faucet on a sink, a house plant, a desk lamp, a microwave or
/// toaster on a counter, a safe on a shelf) are not contents.
const CONTENT_TYPES: &[&str] = &[
    "AlarmClock",
    "AluminumFoil",
    "Apple",
    "BaseballBat",
    "BasketBall",
    "Book",
    "Boots",
    "Bottle",
    "Bowl",
    "Box",
    "Bread",
    "ButterKnife",
    "CD",
    "Candle",
    "CellPhone",
    "Cloth",
    "CreditCard",
    "Cup",
    "DishSponge",
    "Dumbbell",
    "Egg",
    "Fork",
    "HandTowel",
    "Kettle",
    "KeyChain",
    "Knife",
    "Ladle",
    "Laptop",
    "Lettuce",
    "Mug",
    "Newspaper",
    "Pan",
    "PaperTowelRoll",
    "Pen",
    "Pencil",
    "PepperShaker",
    "Pillow",
    "Plate",
    "Plunger",
    "Pot",
    "Potato",
    "RemoteControl",
    "SaltShaker",
    "ScrubBrush",
    "SoapBar",
    "SoapBottle",
    "Spatula",
    "Spoon",
    "SprayBottle",
    "Statue",
    "TableTopDecor",
    "TeddyBear",
    "TennisRacket",
    "TissueBox",
    "ToiletPaper",
    "Tomato",
    "Towel",
    "Vase",
    "Watch",
    "WateringCan",
    "WineBottle",
];

/// True when a child object of this type is a searchable content of its container.
pub fn is_searchable_content(t: &ObjectType) -> bool {
    CONTENT_TYPES.contains(&t.as_str())
}

/// Types that hang on walls. They take no floor space, so the reader keeps them off the map
/// rather than turning them into obstacles that would block the floor along the wall.
pub fn is_wall_mounted(t: &ObjectType) -> bool {
    matches!(
        t.as_str(),
        "Painting" | "Window" | "Blinds" | "LightSwitch" | "ShowerHead"
    )
}

/// Footprint size (metres along the object's own x and z axes: width, then depth front to back)
/// used when no asset database gives the real bounding box. The sizes are typical household
/// dimensions of our own. The house generator uses the same table, so generated houses load with
/// the footprints they were built with.
pub fn default_footprint_size(t: &ObjectType) -> (f64, f64) {
    match t.as_str() {
        "Bed" => (1.4, 2.0),
        "DogBed" => (0.8, 0.6),
        "Sofa" => (1.8, 0.85),
        "ArmChair" => (0.85, 0.85),
        "Chair" => (0.5, 0.55),
        "Stool" | "Footstool" => (0.4, 0.4),
        "Ottoman" => (0.7, 0.7),
        "DiningTable" => (1.2, 0.8),
        "CoffeeTable" => (1.1, 0.6),
        "SideTable" => (0.5, 0.45),
        "Desk" => (1.2, 0.6),
        "TVStand" => (1.3, 0.45),
        "Dresser" => (1.0, 0.5),
        "ShelvingUnit" | "Shelf" => (0.9, 0.4),
        "Cabinet" => (0.8, 0.5),
        "CounterTop" => (2.4, 0.65),
        "Fridge" => (0.8, 0.75),
        "Sink" | "SinkBasin" => (0.6, 0.5),
        "Toilet" => (0.45, 0.7),
        "Bathtub" | "BathtubBasin" => (1.7, 0.75),
        "GarbageCan" => (0.35, 0.35),
        "GarbageBag" => (0.4, 0.4),
        "Box" => (0.4, 0.4),
        "Cart" => (0.6, 0.45),
        "LaundryHamper" => (0.5, 0.4),
        "WashingMachine" | "ClothesDryer" => (0.6, 0.6),
        "Safe" => (0.45, 0.45),
        "FloorLamp" => (0.35, 0.35),
        "HousePlant" => (0.4, 0.4),
        "VacuumCleaner" => (0.3, 0.3),
        "Television" => (1.0, 0.2),
        "Painting" => (0.8, 0.05),
        "RoomDecor" => (0.3, 0.3),
        "Microwave" => (0.5, 0.4),
        "CoffeeMachine" | "Toaster" => (0.3, 0.25),
        other if is_searchable_content(&ObjectType::new(other)) => (0.2, 0.2),
        _ => (0.5, 0.5),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ty(asset: &str) -> Option<String> {
        object_type_for_asset(asset).map(|t| t.0)
    }

    #[test]
    fn words_drop_prefix_numbers_and_variants() {
        assert_eq!(words("RoboTHOR_sofa_kramfors"), ["sofa", "kramfors"]);
        assert_eq!(words("Countertop_C_10x8"), ["countertop", "c"]);
        assert_eq!(words("Wall_Decor_Photo_2V"), ["wall", "decor", "photo"]);
        assert_eq!(words("Hand_Towel_Holder1"), ["hand", "towel", "holder"]);
        assert_eq!(words("RoboTHOR_apple_ai2_1_v"), ["apple", "ai"]);
        assert!(words("").is_empty());
        assert!(words("___").is_empty());
    }

    #[test]
    fn asset_ids_of_common_furniture_map_to_their_types() {
        assert_eq!(ty("RoboTHOR_sofa_kramfors").as_deref(), Some("Sofa"));
        assert_eq!(ty("Countertop_C_10x8").as_deref(), Some("CounterTop"));
        assert_eq!(ty("bin_8").as_deref(), Some("GarbageCan"));
        assert_eq!(ty("Fridge_16").as_deref(), Some("Fridge"));
    }

    #[test]
    fn specific_names_win_over_the_words_they_contain() {
        assert_eq!(ty("Armchair_201_1").as_deref(), Some("ArmChair"));
        assert_eq!(ty("RoboTHOR_office_chair_allak").as_deref(), Some("Chair"));
        assert_eq!(ty("Desk_Lamp_3").as_deref(), Some("DeskLamp"));
        assert_eq!(ty("Desk_304_1").as_deref(), Some("Desk"));
        assert_eq!(ty("Dog_Bed_1_1").as_deref(), Some("DogBed"));
        assert_eq!(ty("Dog_Statue_2").as_deref(), Some("Statue"));
        assert_eq!(ty("Towel_Statue_1").as_deref(), Some("Statue"));
        assert_eq!(ty("Bathtub_Faucet_3").as_deref(), Some("Faucet"));
        assert_eq!(ty("RoboTHOR_hemnes_day_bed").as_deref(), Some("Bed"));
        assert_eq!(ty("Toilet_Paper_Used_Up").as_deref(), Some("ToiletPaper"));
        assert_eq!(
            ty("Toilet_Paper_Hanger_4").as_deref(),
            Some("ToiletPaperHanger")
        );
        assert_eq!(ty("Toilet_2").as_deref(), Some("Toilet"));
        assert_eq!(ty("Pencil_3").as_deref(), Some("Pencil"));
        assert_eq!(ty("Pen_3").as_deref(), Some("Pen"));
        assert_eq!(ty("Potato_3").as_deref(), Some("Potato"));
        assert_eq!(ty("Pot_3").as_deref(), Some("Pot"));
        assert_eq!(ty("Clothes_Dryer_1").as_deref(), Some("ClothesDryer"));
        assert_eq!(ty("Cloth_3").as_deref(), Some("Cloth"));
        assert_eq!(ty("DecorativeBox2").as_deref(), Some("Box"));
        assert_eq!(ty("Tissue_Box_1").as_deref(), Some("TissueBox"));
        assert_eq!(ty("Bath_Towel_Holder1").as_deref(), Some("TowelHolder"));
        assert_eq!(ty("Hand_Towel_Holder1").as_deref(), Some("HandTowelHolder"));
        assert_eq!(ty("CD_1").as_deref(), Some("CD"));
        assert_eq!(
            ty("RoboTHOR_garbage_bin_ai2_1_v").as_deref(),
            Some("GarbageCan")
        );
    }

    #[test]
    fn salt_and_pepper_shakers_are_told_apart() {
        let salt = "RoboTHOR_salt_pepper_shaker_bnyd_salt_v";
        let pepper = "RoboTHOR_salt_pepper_shaker_bnyd_pepper_v";
        assert_eq!(ty(salt).as_deref(), Some("SaltShaker"));
        assert_eq!(ty(pepper).as_deref(), Some("PepperShaker"));
        assert_eq!(ty("Salt_Shaker_1").as_deref(), Some("SaltShaker"));
        assert_eq!(ty("Pepper_Shaker_2").as_deref(), Some("PepperShaker"));
    }

    #[test]
    fn short_words_do_not_match_longer_names() {
        assert_eq!(ty("Pantry_1"), None);
        assert_eq!(ty("Cupboard_1"), None);
        assert_eq!(ty("Bedside_1"), None);
        assert_eq!(ty(""), None);
        assert_eq!(ty("42"), None);
    }

    #[test]
    fn containers_exclude_seating_and_contents_exclude_furniture() {
        for t in [
            "Fridge",
            "CounterTop",
            "Bed",
            "Sofa",
            "GarbageCan",
            "TVStand",
        ] {
            assert!(is_container_type(&ObjectType::new(t)), "{t}");
        }
        for t in ["Chair", "Stool", "FloorLamp", "Painting", "Television"] {
            assert!(!is_container_type(&ObjectType::new(t)), "{t}");
        }
        for t in ["RemoteControl", "CellPhone", "Egg", "Pillow", "Book"] {
            assert!(is_searchable_content(&ObjectType::new(t)), "{t}");
        }
        for t in [
            "Television",
            "Faucet",
            "Chair",
            "HousePlant",
            "Microwave",
            "DeskLamp",
        ] {
            assert!(!is_searchable_content(&ObjectType::new(t)), "{t}");
        }
    }

    #[test]
    fn default_footprints_are_positive_and_beds_are_long() {
        for t in CONTAINER_TYPES.iter().chain(CONTENT_TYPES) {
            let (x, z) = default_footprint_size(&ObjectType::new(*t));
            assert!(x > 0.0 && z > 0.0 && x < 3.0 && z < 3.0, "{t}: {x} x {z}");
        }
        let (x, z) = default_footprint_size(&ObjectType::new("Bed"));
        assert!(z > x);
        assert_eq!(
            default_footprint_size(&ObjectType::new("Unheard")),
            (0.5, 0.5)
        );
    }
}
