//! Configuration tests of `[oee]`: the shift calendar, planned-stop and
//! setup modes, ideal cycle times and the reject tag, every mistake at its
//! place.

use super::*;
use crate::config::oee::RejectTag;

fn with(oee: &str) -> String {
    GOOD.replace(
        "[zenoh.tls]",
        &format!("[[state.modes]]\nid = \"setup\"\nwhen = \"X2\"\nsuppress = [\"fig6\"]\n\n{oee}\n[zenoh.tls]"),
    )
}

#[test]
fn off_by_default_and_a_full_section_is_taken() {
    let c = parse("cell.toml", GOOD, Path::new("base"), &mem()).unwrap();
    assert!(c.oee.is_none());
    let text = with(concat!(
        "[oee]\nutc_offset = \"+09:00\"\nideal_cycle = \"30s\"\nsmall_stop = \"2m\"\n",
        "setup = [\"setup\"]\nreject_signal = \"x1\"\n",
        "[[oee.shifts]]\nname = \"early\"\ndays = [\"mon\", \"tue\"]\nstart = \"06:00\"\nend = \"14:00\"\nbreaks = [\"10:00-10:15\"]\n",
        "[[oee.items]]\nitem = \"A-1\"\nideal_cycle = \"45s\"\n",
    ));
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    let o = c.oee.as_ref().unwrap();
    assert_eq!(o.rejects, Some(RejectTag::Signal(0)));
    let r = &o.rules;
    assert_eq!(r.calendar.utc_offset_ms, 9 * 3_600_000);
    assert_eq!((r.ideal_cycle_ms, r.small_stop_ms), (30_000, 120_000));
    assert_eq!(r.items["A-1"], 45_000);
    assert_eq!(r.setup, ["setup"]);
    let s = &r.calendar.shifts[0];
    assert_eq!(
        (s.start, s.end, s.breaks.as_slice()),
        (360, 840, &[(600, 615)][..])
    );
    assert_eq!(s.days, [true, true, false, false, false, false, false]);
    assert_eq!(
        c.reject_counting(),
        cellwatch_models::engine::PartCounting::Edge(0)
    );
}

#[test]
fn every_mistake_in_oee_is_an_error_at_its_place() {
    let text = with(concat!(
        "[oee]\nutc_offset = \"9h\"\nsmall_stop = \"soon\"\nplanned_stops = [\"lunch\"]\n",
        "reject_counter = \"x1\"\n",
        "[[oee.shifts]]\nname = \"early\"\ndays = [\"monday\"]\nstart = \"6\"\nend = \"14:00\"\nbreaks = [\"10:00\"]\n",
        "[[oee.shifts]]\nname = \"early\"\nstart = \"14:00\"\nend = \"22:00\"\n",
        "[[oee.items]]\nitem = \"A\"\nideal_cycle = \"0s\"\n",
    ));
    assert_eq!(
        errors(&text),
        [
            "cell.toml:29:14: oee.utc_offset: '9h' is not an offset from UTC; write it as +09:00 or -05:30",
            "cell.toml:30:14: oee.small_stop: 'soon' is not a duration longer than zero; write e.g. 45s, 5m",
            "cell.toml:45:15: oee.items[0].ideal_cycle: '0s' is not a duration longer than zero; write e.g. 45s, 5m",
            "cell.toml:28:1: oee.ideal_cycle: required: the ideal cycle time of an item not listed, like \"30s\"",
            "cell.toml:31:18: oee.planned_stops[0]: 'lunch' is no machine mode of [[state.modes]]",
            "cell.toml:36:9: oee.shifts[0].start: '6' is not a time of day; write it as 06:00",
            "cell.toml:35:9: oee.shifts[0].days: 'monday' is not a weekday; write mon, tue, wed, thu, fri, sat or sun",
            "cell.toml:38:11: oee.shifts[0].breaks: '10:00' is not a break; write it as 10:00-10:15",
            "cell.toml:40:8: oee.shifts[1].name: 'early' is named twice",
            "cell.toml:32:18: oee.reject_counter: 'x1' is not an integer tag: a reject counter counts increments",
        ]
        .join("\n")
    );
    let text = with(
        "[oee]\nideal_cycle = \"1m\"\nreject_signal = \"nope\"\n[[oee.shifts]]\nname = \"a\"\nstart = \"00:00\"\nend = \"00:00\"\n",
    );
    assert_eq!(
        errors(&text),
        "cell.toml:30:17: oee.reject_signal: 'nope' is no configured tag"
    );
    let text = with("[oee]\nideal_cycle = \"1m\"\n");
    assert_eq!(
        errors(&text),
        "cell.toml:28:1: oee.shifts: give at least one [[oee.shifts]]: OEE is judged over planned production time"
    );
}
