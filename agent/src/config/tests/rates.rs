//! Configuration tests of the rate-of-change levels of `[[checks.limit]]`
//! (`rising`, `falling`): a good one parses into the check, every mistake
//! is reported at its place.

use cellwatch_models::limit::{RateDirection, RateLevel};

use super::checks::typed;
use super::*;

#[test]
fn rate_levels_parse_beside_or_instead_of_value_levels() {
    let text = typed(
        "[[checks.limit]]\nid = \"t\"\ntag = \"D1\"\nhysteresis = 0.5\n\
         rising = { rate = 5.0, per = \"1m\", severity = \"critical\" }\nfalling = { rate = 2, per = \"30s\" }\n\n\
         [[checks.limit]]\nid = \"u\"\ntag = \"D2\"\nh = { limit = 80.0 }\nrising = { rate = 10.0, per = \"1h\" }\n",
    );
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    let t = &c.limits[0];
    assert!(t.levels.is_empty());
    assert_eq!(
        t.rates,
        [
            RateLevel {
                direction: RateDirection::Rising,
                rate: 5.0,
                per: 60_000,
                severity: Severity::Critical,
            },
            RateLevel {
                direction: RateDirection::Falling,
                rate: 2.0,
                per: 30_000,
                severity: Severity::High,
            },
        ]
    );
    assert_eq!(t.rate_alarm_id(RateDirection::Rising), "t-roc-rising");
    assert_eq!(t.rate_alarm_id(RateDirection::Falling), "t-roc-falling");
    assert_eq!(c.limits[1].levels.len(), 1);
    assert_eq!(c.limits[1].rates[0].per, 3_600_000);
    // The engine takes them.
    crate::cell::compile::engine(&c).unwrap();
}

#[test]
fn bad_rate_levels_are_reported_at_their_place() {
    let bad = typed(
        "[[checks.limit]]\nid = \"t\"\ntag = \"D1\"\nhysteresis = 2.0\n\
         rising = { rate = 0.0, per = \"500ms\" }\n\
         falling = { rate = 1.5, per = \"2h\", severity = \"loud\" }\n\n\
         [[checks.limit]]\nid = \"u\"\ntag = \"D1\"\n\
         rising = { rate = -1, per = \"0s\" }\nfalling = { rate = nan, per = \"soon\" }\n",
    );
    assert_eq!(
        errors(&bad),
        "cell.toml:45:19: checks.limit[0].rising.rate: 0 must be more than zero\n\
         cell.toml:45:30: checks.limit[0].rising.per: at least 1s\n\
         cell.toml:46:20: checks.limit[0].falling.rate: 1.5 must be more than the hysteresis 2: a raised alarm would never clear while the value holds still\n\
         cell.toml:46:31: checks.limit[0].falling.per: at most 1h\n\
         cell.toml:46:48: checks.limit[0].falling.severity: unknown severity 'loud': use low, medium, high or critical\n\
         cell.toml:51:19: checks.limit[1].rising.rate: -1 must be more than zero\n\
         cell.toml:51:29: checks.limit[1].rising.per: must be longer than zero\n\
         cell.toml:52:20: checks.limit[1].falling.rate: must be a finite number\n\
         cell.toml:52:31: checks.limit[1].falling.per: 'soon' is not a duration (expected number at 0); write e.g. 100ms, 2s, 30d"
    );
}

#[test]
fn a_rate_level_takes_no_unknown_key_and_needs_its_rate_and_window() {
    let check = |level: &str| {
        errors(&typed(&format!(
            "[[checks.limit]]\nid = \"t\"\ntag = \"D1\"\n{level}\n"
        )))
    };
    let seen = [
        check("rising = { rate = 1.0, per = \"1m\", limit = 3.0 }"),
        check("falling = { rate = 1.0 }"),
        check("unit = \"bar\""),
    ];
    assert_eq!(
        seen,
        [
            "cell.toml:44:36: unknown field `limit`, expected one of `rate`, `per`, `severity`",
            "cell.toml:44:11: missing field `per`",
            "cell.toml:42:6: checks.limit[0]: give at least one level: hh, h, l or ll = { limit = ..., severity = ... }, \
             or a rate: rising or falling = { rate = ..., per = ... }",
        ]
    );
}

#[test]
fn the_how_to_example_parses() {
    let doc = include_str!("../../../../docs/how-to/numeric-limits.md");
    let section = &doc[doc.find("## Rate-of-change alarms").unwrap()..];
    let start = section.find("```toml\n").unwrap() + "```toml\n".len();
    let example = &section[start..start + section[start..].find("```").unwrap()];
    let text = GOOD.replace(
        "[[checks.switching]]",
        &format!(
            "[[tags]]\nname = \"spindle_temperature\"\nnode_id = \"nsu=urn:plc;s=D100\"\naddress = \"D100\"\ntype = \"Double\"\n\n\
             {example}\n[[checks.switching]]"
        ),
    );
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    let l = &c.limits[0];
    assert_eq!((l.levels.len(), l.rates.len()), (1, 2));
    assert_eq!(l.rates[1].direction, RateDirection::Falling);
    assert_eq!(l.rates[1].per, 30_000);
    assert_eq!(l.rates[1].severity, Severity::Medium);
}
