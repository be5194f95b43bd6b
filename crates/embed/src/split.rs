//! Splitting type names into words.

/// Splits a type name into lowercase words.
///
/// Boundaries are:
/// - any character that is not a letter or digit (`_`, `-`, spaces, dots, …), which is dropped;
/// - a lowercase letter followed by an uppercase one (`CounterTop` → `counter`, `top`);
/// - the end of an acronym: an uppercase letter followed by an uppercase letter and then a
///   lowercase one starts a new word (`TVStand` → `tv`, `stand`; `DVDPlayer` → `dvd`,
///   `player`). A lone `s` after an acronym is kept as its plural (`TVs` → `tvs`) rather than
///   split into `t`, `vs`;
/// - a change between digits and letters (`Pillow2` → `pillow`, `2`).
///
/// Names are ambiguous where an acronym meets a word whose second letter is `s` (`TVIs` reads
/// as `tvis`) or a one-letter word (`AATable`); ProcTHOR's names have neither.
///
/// Pure digit runs are then dropped (`Pillow2` → `pillow`, `Bed_1` → `bed`): in ProcTHOR names
/// they number instances or variants and carry no meaning, while a vector for `2` would pull
/// every numbered name towards the others. Words mixing letters and digits cannot occur, since
/// digits always form their own runs.
///
/// ```
/// use ferret_embed::split_name;
/// assert_eq!(split_name("TVStand"), ["tv", "stand"]);
/// assert_eq!(split_name("Pillow_2"), ["pillow"]);
/// ```
pub fn split_name(name: &str) -> Vec<String> {
    let mut words = Vec::new();
    for part in name.split(|c: char| !c.is_alphanumeric()) {
        split_part(part, &mut words);
    }
    words
}

/// Splits one run of letters and digits at case and digit boundaries.
fn split_part(part: &str, words: &mut Vec<String>) {
    let chars: Vec<char> = part.chars().collect();
    let mut start = 0;
    for i in 1..chars.len() {
        let prev = chars[i - 1];
        let cur = chars[i];
        let next = chars.get(i + 1).copied();
        let after_next = chars.get(i + 2).copied();
        let camel = prev.is_lowercase() && cur.is_uppercase();
        // `TVs`: the `s` closes the acronym (a plural) unless more lowercase letters follow.
        let plural_s = next == Some('s') && !after_next.is_some_and(char::is_lowercase);
        let acronym_end = prev.is_uppercase()
            && cur.is_uppercase()
            && next.is_some_and(char::is_lowercase)
            && !plural_s;
        let digits = prev.is_numeric() != cur.is_numeric();
        if camel || acronym_end || digits {
            push_word(&chars[start..i], words);
            start = i;
        }
    }
    push_word(&chars[start..], words);
}

/// Adds a word in lowercase, unless it is empty or only digits.
fn push_word(chars: &[char], words: &mut Vec<String>) {
    if chars.is_empty() || chars.iter().all(|c| c.is_numeric()) {
        return;
    }
    words.push(chars.iter().flat_map(|c| c.to_lowercase()).collect());
}

#[cfg(test)]
mod tests {
    use super::split_name;
    use proptest::prelude::*;

    #[test]
    fn procthor_names() {
        let cases: &[(&str, &[&str])] = &[
            ("CounterTop", &["counter", "top"]),
            ("TVStand", &["tv", "stand"]),
            ("DVDPlayer", &["dvd", "player"]),
            ("RemoteControl", &["remote", "control"]),
            ("LivingRoom", &["living", "room"]),
            ("Bathroom", &["bathroom"]),
            ("DiningTable", &["dining", "table"]),
            ("ShelvingUnit", &["shelving", "unit"]),
            ("HousePlant", &["house", "plant"]),
            ("Spatula", &["spatula"]),
            ("SoapBottle", &["soap", "bottle"]),
            ("TV", &["tv"]),
            ("TVs", &["tvs"]),
            ("PCsAndTVs", &["pcs", "and", "tvs"]),
            ("Pillow2", &["pillow"]),
            ("Bed_1", &["bed"]),
            ("garbage-can", &["garbage", "can"]),
            ("Coffee Table", &["coffee", "table"]),
            ("alarmClock", &["alarm", "clock"]),
            ("Shelf3Top", &["shelf", "top"]),
            ("", &[]),
            ("_-_ 42", &[]),
        ];
        for (name, want) in cases {
            assert_eq!(split_name(name), *want, "split_name({name:?})");
        }
    }

    /// Real words that appear in ProcTHOR type names, capitalised as they appear there. No
    /// one-letter words: `AA` cannot be told from an acronym.
    const WORDS: &[&str] = &[
        "Counter", "Top", "Stand", "Remote", "Control", "Living", "Room", "Bath", "Dining",
        "Table", "Shelving", "Unit", "House", "Plant", "Spatula", "Soap", "Bottle", "Is",
    ];
    const ACRONYMS: &[&str] = &["TV", "DVD", "CD", "USB", "PC"];

    fn capitalised() -> impl Strategy<Value = String> {
        prop_oneof![
            proptest::sample::select(WORDS).prop_map(str::to_owned),
            // Arbitrary words; the second letter is not `s`, so that an acronym before them is
            // never read as a plural (`TVSx` vs `TVs` + `x` is genuinely ambiguous).
            ("[A-Z]", "[a-rt-z]", "[a-z]{0,6}").prop_map(|(a, b, c)| format!("{a}{b}{c}")),
        ]
    }

    proptest! {
        /// Joining capitalised words back to back and splitting gives back the words, lowercase.
        #[test]
        fn camel_case_round_trip(words in proptest::collection::vec(capitalised(), 1..6)) {
            let name: String = words.concat();
            let want: Vec<String> = words.iter().map(|w| w.to_lowercase()).collect();
            prop_assert_eq!(split_name(&name), want);
        }

        /// An acronym followed by a capitalised word splits between the two.
        #[test]
        fn acronym_then_word(
            acronym in proptest::sample::select(ACRONYMS),
            // `TVIs` reads as the plural `TVs` + `I`: a word whose second letter is `s` is ambiguous
            // after an acronym.
            word in capitalised().prop_filter("ambiguous after an acronym", |w| !w[1..].starts_with('s')),
        ) {
            let name = format!("{acronym}{word}");
            prop_assert_eq!(split_name(&name), vec![acronym.to_lowercase(), word.to_lowercase()]);
        }

        /// Separators and instance numbers between words change nothing.
        #[test]
        fn separators_and_digits_are_dropped(
            words in proptest::collection::vec(capitalised(), 1..5),
            seps in proptest::collection::vec(prop_oneof![
                Just("_".to_owned()), Just("-".to_owned()), Just(" ".to_owned()),
                "[0-9]{1,3}", "_[0-9]{1,3}_",
            ], 5),
        ) {
            let mut name = String::new();
            for (w, s) in words.iter().zip(&seps) {
                name.push_str(w);
                name.push_str(s);
            }
            let want: Vec<String> = words.iter().map(|w| w.to_lowercase()).collect();
            prop_assert_eq!(split_name(&name), want);
        }
    }
}
