//! What several subcommands accept, defined once: the defaults every command shares and the
//! value parsers whose `--help` lists every accepted value.

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use portico_client::elision::Algorithm;
use portico_data::frame::{LengthUnit, UpAxis};
use portico_generator::Preset;

/// Image size of every command that renders (`walk`, `bench`, `demo`).
pub const SIZE: &str = "640x480";
/// Legs of a generated tour (`path`, `walk`, `loadtest`, `bench`, `demo`).
pub const LEGS: usize = 4;

/// `--preset`: the generator's building sizes.
pub fn preset() -> impl TypedValueParser<Value = Preset> {
    PossibleValuesParser::new([
        PossibleValue::new("tiny").help("1 storey, a few rooms (tests)"),
        PossibleValue::new("small").help("2 storeys, 47 rooms (the demo)"),
        PossibleValue::new("soda").help("7 storeys, 390 rooms: Soda Hall's scale"),
        PossibleValue::new("mega").help("18 storeys, 3,571 rooms: 10x Soda Hall"),
    ])
    .map(|s| s.parse().expect("every listed preset parses"))
}

/// `--units` of `build`: the length units a model file may be in.
pub fn unit() -> impl TypedValueParser<Value = LengthUnit> {
    PossibleValuesParser::new(
        LengthUnit::ALL.map(|u| PossibleValue::new(u.symbol()).help(u.name())),
    )
    .map(|s| LengthUnit::parse(&s).expect("every listed unit parses"))
}

/// `--up` of `build`: the axis pointing up in a model file.
pub fn up() -> impl TypedValueParser<Value = UpAxis> {
    PossibleValuesParser::new([
        PossibleValue::new("y").help("Y up (glTF, most OBJ)"),
        PossibleValue::new("z").help("Z up (IFC, Revit, 3ds Max, Rhino)"),
    ])
    .map(|s| UpAxis::parse(&s).expect("every listed axis parses"))
}

/// `--elision`: the detail elision algorithms of the client.
pub fn elision() -> impl TypedValueParser<Value = Algorithm> {
    PossibleValuesParser::new(ELISION.map(|(name, help)| PossibleValue::new(name).help(help)))
        .map(|s| s.parse().expect("every listed algorithm parses"))
}

/// `--algorithms` of `bench`: `regular` and every elision algorithm.
pub fn bench_run() -> PossibleValuesParser {
    let regular = PossibleValue::new("regular")
        .help("every object at its finest LOD, everything resident: the fidelity reference");
    PossibleValuesParser::new(
        std::iter::once(regular).chain(ELISION.map(|(n, h)| PossibleValue::new(n).help(h))),
    )
}

/// `--sweep` of `loadtest`: Funkhouser §5.3's policy grids.
pub fn sweep() -> PossibleValuesParser {
    PossibleValuesParser::new([
        PossibleValue::new("reduced").help("13 policies across every parameter (the default)"),
        PossibleValue::new("full").help("all 144 policies"),
        PossibleValue::new("depth").help("lookahead depth 1-64 frames (Table 5.1)"),
        PossibleValue::new("gran").help("object against cell granularity (Table 5.3)"),
        PossibleValue::new("cull").help("range and lookahead culls (Tables 5.5-5.10)"),
    ])
}

/// The elision algorithms with one line each.
const ELISION: [(&str, &str); 6] = [
    ("none", "the finest LOD of every object, whatever it costs"),
    (
        "static",
        "the finest LOD whose average triangle covers >= 1024 pixels",
    ),
    (
        "feedback",
        "static, its threshold adapted to the last frame time",
    ),
    (
        "optimize",
        "cost/benefit optimisation within the frame budget",
    ),
    (
        "impostors",
        "optimize, with far clusters drawn as textured boxes",
    ),
    ("coarsest", "every object at its coarsest resident LOD"),
];

/// Help of `--policy`: every key and its values.
pub const POLICY_HELP: &str = "Prefetch policy, comma-separated key=value pairs (Funkhouser \
§5.3): depth=FRAMES (lookahead, default 16), gran=object|cell, range=any|plane|frustum|direction, \
look=any|plane|frustum, read=BYTES per answer (e.g. 4m, 512k), size=PIXELS per triangle (the \
static size threshold), imp=0|1 (list impostor atlases), bc=0|1 (the load tester's clients hold textures \
block-compressed: BC1/BC3, at most a byte per texel; a real client says what its GPU holds). \
Unset keys keep their defaults";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_value_parses() {
        for (name, _) in ELISION {
            assert_eq!(name.parse::<Algorithm>().unwrap().name(), name);
        }
        for p in ["tiny", "small", "soda", "mega"] {
            p.parse::<Preset>().unwrap();
        }
        for r in bench_run().possible_values().unwrap() {
            portico_lab::bench::RunKind::parse_list(r.get_name()).unwrap();
        }
        for g in sweep().possible_values().unwrap() {
            portico_lab::loadtest::grid(g.get_name(), Default::default()).unwrap();
        }
    }
}
