//! Two-valued protocol choices the world crate acts on: which top-level objects are containers,
//! where the robot stands to search one, and how a trial's travel is reported. The planning
//! crate gathers them, with its own, into a protocol.

/// Declares a two-valued option: an enum (the first value the default) that parses from and
/// prints as its command-line names and serialises as them in lower case.
#[doc(hidden)]
#[macro_export]
macro_rules! two_way_option {
    ($(#[$doc:meta])* $name:ident { $(#[$da:meta])* $a:ident = $sa:literal, $(#[$db:meta])* $b:ident = $sb:literal $(,)? }) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, ::serde::Serialize, ::serde::Deserialize)]
        pub enum $name {
            $(#[$da])*
            #[default]
            #[serde(rename = $sa)]
            $a,
            $(#[$db])*
            #[serde(rename = $sb)]
            $b,
        }

        impl $name {
            /// The option's values, default first.
            pub const VALUES: [&'static str; 2] = [$sa, $sb];
        }

        impl ::std::str::FromStr for $name {
            type Err = String;

            fn from_str(s: &str) -> Result<Self, Self::Err> {
                match s {
                    $sa => Ok(Self::$a),
                    $sb => Ok(Self::$b),
                    _ => Err(format!("`{s}`: expected `{}` or `{}`", $sa, $sb)),
                }
            }
        }

        impl ::std::fmt::Display for $name {
            fn fmt(&self, f: &mut ::std::fmt::Formatter<'_>) -> ::std::fmt::Result {
                f.write_str(match self {
                    Self::$a => $sa,
                    Self::$b => $sb,
                })
            }
        }
    };
}

two_way_option!(
    /// Which top-level objects of a ProcTHOR house are containers.
    ContainerSet {
        /// Receptacle types of the asset database, wall-mounted ones left out (ferret).
        Receptacles = "receptacles",
        /// The reference code: every top-level object except 15 ignored types, each holding its
        /// direct children whose type is not a top-level type of the house.
        Furniture = "furniture",
    }
);

two_way_option!(
    /// Where the robot stands to search a container.
    AccessRule {
        /// The reachable cell of the container's room nearest its footprint, facing the middle
        /// of a side (ferret).
        Footprint = "footprint",
        /// The reference code: the reachable cell nearest the container's centre, in any room.
        NearestFree = "nearest-free",
    }
);

two_way_option!(
    /// How the reported cost of a trial is measured; planners always decide on plain distances.
    TravelCost {
        /// The plain shortest-path length the planners use (ferret).
        Plain = "plain",
        /// The reference code's soft cost, dearer near obstacles (see [`crate::soft`]).
        Soft = "soft",
    }
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for v in ContainerSet::VALUES {
            assert_eq!(v.parse::<ContainerSet>().unwrap().to_string(), v);
        }
        assert_eq!(
            "nearest-free".parse::<AccessRule>(),
            Ok(AccessRule::NearestFree)
        );
        assert_eq!(
            serde_json::to_string(&AccessRule::NearestFree).unwrap(),
            "\"nearest-free\""
        );
        assert!("metres".parse::<TravelCost>().is_err());
        assert_eq!(TravelCost::default(), TravelCost::Plain);
    }
}
