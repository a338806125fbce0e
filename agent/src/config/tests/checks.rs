//! Configuration tests of tags and the checks that read them: types,
//! limits, counters, charts, tags files, STL addresses, ids.

use super::*;

#[test]
fn timer_model_signals_must_be_tags() {
    let text = format!("{GOOD}\n[[checks.timers]]\nid = \"line\"\nmodel = \"timers.json\"\n");
    assert_eq!(
        errors(&text),
        "cell.toml:30:9: checks.timers[0].model: the model reads belt, which no tag has as name or address"
    );
    let ok = text.clone();
    let mut files = mem();
    files.0.insert(
        PathBuf::from("base/timers.json"),
        br#"{"version": 1, "method": "common", "signals": ["x1", "X2"], "transitions": []}"#
            .to_vec(),
    );
    let c = parse("cell.toml", &ok, Path::new("base"), &files).unwrap();
    assert_eq!(c.timers[0].id, "line");
    assert_eq!(
        timer_signal(c.addressing, &c.tags, "x1"),
        Some(Signal::new("X1"))
    );
    assert_eq!(
        timer_signal(c.addressing, &c.tags, "X2"),
        Some(Signal::new("X2"))
    );
    // Drift warnings are on, with the model's defaults, unless said.
    assert_eq!(
        c.timers[0].drift,
        Some(cellwatch_models::timer::drift::DriftRules::default())
    );
    let off = parse(
        "cell.toml",
        &format!("{ok}drift = false\n"),
        Path::new("base"),
        &files,
    )
    .unwrap();
    assert_eq!(off.timers[0].drift, None);
    let tuned = parse(
        "cell.toml",
        &format!("{ok}drift_fraction = 0.3\ndrift_min_samples = 50\n"),
        Path::new("base"),
        &files,
    )
    .unwrap();
    let rules = tuned.timers[0].drift.unwrap();
    assert_eq!((rules.fraction, rules.min_samples), (0.3, 50));
    let e = parse(
        "cell.toml",
        &format!("{ok}drift_fraction = 1.5\ndrift_weight = 0.0\n"),
        Path::new("base"),
        &files,
    )
    .unwrap_err()
    .to_string();
    assert_eq!(
        e,
        "cell.toml:31:18: checks.timers[0].drift_fraction: fraction must be in (0, 1], not 1.5\n\
         cell.toml:32:16: checks.timers[0].drift_weight: weight must be in (0, 1], not 0"
    );
}

/// GOOD with numeric tags `D1` (Double) and `D2` (UInt16) and `S1`
/// (String) added before the checks, and `extra` appended.
pub(super) fn typed(extra: &str) -> String {
    GOOD.replace(
        "[[checks.switching]]",
        "[[tags]]\nname = \"temp\"\nnode_id = \"nsu=urn:plc;s=D1\"\naddress = \"D1\"\ntype = \"Double\"\n\n\
         [[tags]]\nname = \"count\"\nnode_id = \"nsu=urn:plc;s=D2\"\naddress = \"D2\"\ntype = \"UInt16\"\n\n\
         [[tags]]\nname = \"text\"\nnode_id = \"nsu=urn:plc;s=S1\"\naddress = \"S1\"\ntype = \"String\"\n\n\
         [[checks.switching]]",
    )
    .replace("[zenoh.tls]", &format!("{extra}\n[zenoh.tls]"))
}

#[test]
fn typed_tags_limits_counters_and_comparisons() {
    let text = typed(
        "[[checks.limit]]\nid = \"t\"\ntag = \"D1\"\nunit = \"°C\"\ndeadband = 1.5\non_delay = \"2s\"\nh = { limit = 80.0 }\nll = { limit = 0.0, severity = \"low\" }\n\n\
         [state]\nrunning = \"X1 * d1 > 20.5 * D2 != D1\"\n\n[production]\ncounter = \"D2\"\n",
    );
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    assert_eq!(c.tags[2].value_type, ValueType::Double);
    assert_eq!(c.limits[0].alarm_id(Level::H), "t-h");
    assert_eq!(c.limits[0].label, "temp");
    assert_eq!(c.limits[0].on_delay, 2000);
    assert_eq!(c.limits[0].levels[0].severity, Severity::High);
    assert_eq!(c.limits[0].levels[1].severity, Severity::Low);
    let running: Vec<String> = c
        .state
        .running
        .as_ref()
        .unwrap()
        .signals()
        .iter()
        .map(|s| s.to_string())
        .collect();
    assert_eq!(
        running,
        ["D1 > 20.5", "D2 != D1", "X1"],
        "canonical addresses"
    );
    assert_eq!(c.part_counters, [3]);
    // Only the agent's own alarms are delayed unless configured: they
    // clear 10 s after their condition ends.
    assert_eq!(
        c.delays,
        [
            ("communication".to_string(), 0, 10_000),
            ("tag-quality".to_string(), 0, 10_000)
        ]
    );
    let delayed = parse(
        "cell.toml",
        &GOOD.replace(
            "coil = \"G0.00\"",
            "coil = \"G0.00\"\non_delay = \"5s\"\noff_delay = \"1500ms\"",
        ),
        Path::new("base"),
        &mem(),
    )
    .unwrap();
    assert_eq!(delayed.delays[0], ("fig6".to_string(), 5000, 1500));
    assert_eq!(delayed.delays.len(), 3);
    assert!(matches!(
        c.part_counting(),
        PartCounting::Counters(ref cs) if cs.len() == 1 && cs[0].0 == 3 && cs[0].1.max == 65535
    ));
    crate::cell::compile::engine(&c).unwrap();
}

#[test]
fn types_are_checked_where_tags_are_used() {
    let bad = typed(
        "[[checks.limit]]\nid = \"t\"\ntag = \"X1\"\nh = { limit = 80.0 }\n\n\
         [[checks.limit]]\nid = \"u\"\ntag = \"D1\"\nh = { limit = 1.0 }\nhh = { limit = 0.5 }\n\n\
         [state]\nrunning = \"D1 * S1 > 3\"\n\n[production]\ncounter = \"D1\"\n",
    )
    .replace("address = \"X2\"", "address = \"X2\"\nbit = 3");
    assert_eq!(
        errors(&bad),
        "cell.toml:17:7: tags[1].bit: a bit needs an integer type; this tag is Boolean: add type = \"Byte\" (or another integer type)\n\
         cell.toml:44:7: checks.limit[0].tag: X1 is a Boolean: a limit check needs a numeric tag (type = \"Double\", \"Int16\", ...)\n\
         cell.toml:48:6: checks.limit[1]: the limits must fall in the order hh > h > l > ll\n\
         cell.toml:54:11: state.running: D1 is a Double, not a contact: compare it (`D1 > 0`) or give the tag a bit; S1 is a String and cannot be compared as a number (in 'S1 > 3')\n\
         cell.toml:57:11: production.counter: D1 is a Double: a counter must be an integer tag without a bit"
    );
}

/// The cell of the robot charts (`config/robot/robot.sfc.toml`): a tag for
/// every step flag and input the charts read, `drop` of them left out.
fn robot_cell(drop: &str) -> (String, Mem) {
    let charts = include_str!("../../../../config/robot/robot.sfc.toml");
    let sfc = cellwatch_models::sfc::text::parse("robot.sfc.toml", charts, &|_| true).unwrap();
    let mut signals = std::collections::BTreeSet::new();
    for chart in &sfc.charts {
        signals.extend(chart.steps.iter().map(|s| s.flag.clone()));
        for t in &chart.transitions {
            signals.extend(t.condition.signals());
        }
    }
    let mut text = "[cell]\nid = \"robot\"\n\n[opcua]\nendpoint = \"opc.tcp://127.0.0.1:4840/\"\n\n[zenoh.tls]\nca = \"ca.pem\"\ncert = \"a.pem\"\nkey = \"a.key\"\n".to_string();
    for s in signals.iter().filter(|s| s.name() != drop) {
        text += &format!(
            "\n[[tags]]\nname = \"{0}\"\nnode_id = \"nsu=urn:plc;s={0}\"\naddress = \"{0}\"\n",
            s.name()
        );
    }
    text +=
        "\n[[checks.sfc]]\nid = \"sfc\"\ncharts = \"robot.sfc.toml\"\nseverity = \"critical\"\n";
    let mut files = mem();
    files.0.insert(
        PathBuf::from("base/robot.sfc.toml"),
        charts.as_bytes().to_vec(),
    );
    (text, files)
}

#[test]
fn charts_under_supervision_bind_to_the_tags() {
    let (text, files) = robot_cell("");
    let c = parse("cell.toml", &text, Path::new("base"), &files).unwrap();
    assert_eq!(c.sfc.len(), 1);
    assert_eq!(c.sfc[0].severity, Severity::Critical);
    assert_eq!(c.sfc[0].sfc.charts.len(), 2);
    // And the engine takes them: every supervised step can be raised.
    let engine = crate::cell::compile::engine(&c).unwrap();
    drop(engine);
    // A chart reading a contact no tag has is refused at the chart's line.
    let (text, files) = robot_cell("%IX0.0.3");
    let e = parse("cell.toml", &text, Path::new("base"), &files)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("base/robot.sfc.toml:")
            && e.contains("transition t3: unknown contact '%IX0.0.3': no tag has this address"),
        "{e}"
    );
}

#[test]
fn forcing_keys_name_boolean_tags_and_declared_transitions() {
    let (base, files) = robot_cell("");
    let switches = "\n[[tags]]\nname = \"Force\"\nnode_id = \"nsu=urn:plc;s=%IX0.3.1\"\naddress = \"%IX0.3.1\"\n\n[[tags]]\nname = \"Speed\"\nnode_id = \"nsu=urn:plc;s=D1\"\naddress = \"D1\"\ntype = \"Double\"\n";
    // The tags go before the checks.
    let (head, checks) = base.split_at(base.find("\n[[checks.sfc]]").unwrap());
    let text = format!(
        "{head}{switches}{checks}force_switch = \"%IX0.3.1\"\nforcible = [\"F1.t3\", \"F2.t18\"]\nforce_pulse = \"300ms\"\n"
    );
    let c = parse("cell.toml", &text, Path::new("base"), &files).unwrap();
    let s = &c.sfc[0];
    assert_eq!(c.tags[s.force_switch.unwrap()].name, "Force");
    assert_eq!(s.stop_switch, None);
    assert_eq!(
        s.forcible,
        [("F1".into(), "t3".into()), ("F2".into(), "t18".into())]
    );
    assert_eq!(s.force_pulse, Duration::from_millis(300));
    assert_eq!(s.force_timeout, crate::config::DEFAULT_FORCE_TIMEOUT);
    // Each bad key at its place.
    let text = format!(
        "{head}{switches}{checks}force_switch = \"D1\"\nstop_switch = \"%IX9.9.9\"\nforcible = [\"F1.t9\", \"t3\"]\nforce_timeout = \"soon\"\n"
    );
    let e = parse("cell.toml", &text, Path::new("base"), &files)
        .unwrap_err()
        .to_string();
    for want in [
        "checks.sfc[0].force_switch: 'D1' is Double; a switch is a Boolean tag",
        "checks.sfc[0].stop_switch: '%IX9.9.9' is not a tag of this cell",
        "checks.sfc[0].forcible[0]: no transition t9 in a chart F1 of base/robot.sfc.toml",
        "checks.sfc[0].forcible[1]: 't3' is not CHART.TRANSITION (F1.t3)",
        "checks.sfc[0].force_timeout: 'soon' is not a duration",
    ] {
        assert!(e.contains(want), "{want} not in {e}");
    }
    // Forcing without a force switch.
    let text = format!("{head}{switches}{checks}forcible = [\"F1.t3\"]\n");
    let e = parse("cell.toml", &text, Path::new("base"), &files)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("checks.sfc[0].forcible[0]: forcing needs the force switch (force_switch)"),
        "{e}"
    );
}

#[test]
fn learned_step_supervision_fills_the_steps_that_declare_none() {
    let (text, mut files) = robot_cell("");
    let text = format!("{text}steps = \"robot-steps.json\"\n");
    let learned = |step: &str| {
        format!(
            "{{\"step\": \"{step}\", \"supervision_ms\": 2400, \"min_ms\": 1000, \"max_ms\": 1400, \
             \"mean_ms\": 1200, \"count\": 20, \"support\": 4}}"
        )
    };
    let model = format!(
        "{{\"version\": 1, \"runs\": 4, \"steps\": [{}, {}]}}",
        learned("F1.S2"),
        learned("F2.S6")
    );
    files
        .0
        .insert(PathBuf::from("base/robot-steps.json"), model.into_bytes());
    let c = parse("cell.toml", &text, Path::new("base"), &files).unwrap();
    let sfc = &c.sfc[0].sfc;
    let step = |chart: usize, name: &str| {
        sfc.charts[chart]
            .steps
            .iter()
            .find(|s| s.name == name)
            .unwrap()
            .supervision_ms
    };
    // F1.S2 declares 8 s: it keeps it; F2.S6 declares none: learned.
    assert_eq!(step(0, "S2"), Some(8_000));
    assert_eq!(step(1, "S6"), Some(2_400));
    assert_eq!(step(1, "S9"), None);

    // A step the charts lack, a file that is no model, a missing file.
    let model = format!(
        "{{\"version\": 1, \"runs\": 4, \"steps\": [{}]}}",
        learned("F1.S9")
    );
    files
        .0
        .insert(PathBuf::from("base/robot-steps.json"), model.into_bytes());
    let e = parse("cell.toml", &text, Path::new("base"), &files)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(
            "checks.sfc[0].steps: base/robot-steps.json: step F1.S9: no such step in the charts"
        ),
        "{e}"
    );
    files.0.insert(
        PathBuf::from("base/robot-steps.json"),
        b"{\"version\": 1,\n \"runs\": 4, \"stepz\": []}".to_vec(),
    );
    let e = parse("cell.toml", &text, Path::new("base"), &files)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("checks.sfc[0].steps: base/robot-steps.json:2:")
            && e.contains("unknown field `stepz`"),
        "{e}"
    );
    files.0.remove(&PathBuf::from("base/robot-steps.json"));
    let e = parse("cell.toml", &text, Path::new("base"), &files)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("checks.sfc[0].steps: cannot read step supervision 'base/robot-steps.json'"),
        "{e}"
    );
}

#[test]
fn charts_from_plcopen_xml_take_their_supervision_from_the_cell() {
    let (text, mut files) = robot_cell("");
    files.0.insert(
        PathBuf::from("base/robot.sfc.xml"),
        include_bytes!("../../../../config/robot/robot.sfc.xml").to_vec(),
    );
    let text = text.replace("robot.sfc.toml", "robot.sfc.xml");
    let good = format!("{text}supervision = {{ \"F1.S2\" = \"8s\", \"F2.S15\" = \"5s\" }}\n");
    let c = parse("cell.toml", &good, Path::new("base"), &files).unwrap();
    let supervised: Vec<(String, u64)> = c.sfc[0]
        .sfc
        .steps()
        .filter_map(|(r, s)| Some((c.sfc[0].sfc.step_name(r), s.supervision_ms?)))
        .collect();
    assert_eq!(
        supervised,
        [("F1.S2".to_string(), 8_000), ("F2.S15".to_string(), 5_000)]
    );
    let bad = format!("{text}supervision = {{ \"F1.S9\" = \"8s\", \"F2.S15\" = \"soon\" }}\n");
    let e = parse("cell.toml", &bad, Path::new("base"), &files)
        .unwrap_err()
        .to_string();
    for want in [
        "checks.sfc[0].supervision.\"F1.S9\": no step F1.S9 in base/robot.sfc.xml (write CHART.STEP)",
        "checks.sfc[0].supervision.\"F2.S15\": 'soon': write a duration such as 500ms, 8s, 2m or 1h",
    ] {
        assert!(e.contains(want), "{want} not in {e}");
    }
}

/// `GOOD` with its tags in a CSV file.
fn with_tags_file(csv: &str) -> (String, Mem) {
    let start = GOOD.find("[[tags]]").unwrap();
    let end = GOOD.find("[[checks.switching]]").unwrap();
    let text = format!(
        "tags_file = \"tags.csv\"\n{}{}",
        &GOOD[..start],
        &GOOD[end..]
    );
    let mut files = mem();
    files
        .0
        .insert(PathBuf::from("base/tags.csv"), csv.as_bytes().to_vec());
    (text, files)
}

#[test]
fn a_tags_file_gives_the_same_tags_as_tables() {
    let tables = parse("cell.toml", GOOD, Path::new("base"), &mem()).unwrap();
    let (text, files) = with_tags_file(
        "# exported from the PLC's tag table\n\
         name,node_id,address\n\
         x1,nsu=urn:plc;s=X1,X1\n\
         \n\
         \"x2\",\"nsu=urn:plc;s=X2\", X2\n",
    );
    let file = parse("cell.toml", &text, Path::new("base"), &files).unwrap();
    assert_eq!(file.tags, tables.tags);
    assert_eq!(file.switching.len(), 1);

    // Every column of a table, in any order.
    let (text, files) = with_tags_file(
        "address,name,node_id,type,comment,bit,sampling_interval,deadband,deadband_percent,export,max\n\
         X1,x1,nsu=urn:plc;s=X1,,Belt running,,,,,,\n\
         X2,x2,nsu=urn:plc;s=X2,,,,,,,,\n\
         D100,temp,nsu=urn:plc;s=D100,Float,\"Oven, zone 1\",,50ms,0.5,,true,\n\
         D101.3,d3,nsu=urn:plc;s=D101,UInt16,,3,,,,,\n\
         C0,count,nsu=urn:plc;s=C0,UInt16,,,,,,,999\n",
    );
    let c = parse("cell.toml", &text, Path::new("base"), &files).unwrap();
    assert_eq!(c.tags.len(), 5);
    assert_eq!(c.tags[0].comment.as_deref(), Some("Belt running"));
    let temp = &c.tags[2];
    assert_eq!(temp.value_type, cellwatch_models::value::ValueType::Float);
    assert_eq!(temp.comment.as_deref(), Some("Oven, zone 1"));
    assert_eq!(temp.sampling_interval, Some(Duration::from_millis(50)));
    assert_eq!(temp.deadband, Some(crate::config::Deadband::Absolute(0.5)));
    assert!(temp.export);
    assert_eq!(c.tags[3].bit, Some(3));
    assert_eq!(c.tags[4].max, Some(999));
}

#[test]
fn a_tags_file_problem_names_the_file_and_the_line() {
    let check = |csv: &str, want: &[&str]| {
        let (text, files) = with_tags_file(csv);
        let e = parse("cell.toml", &text, Path::new("base"), &files)
            .unwrap_err()
            .to_string();
        for w in want {
            assert!(e.contains(w), "{w:?} not in:\n{e}");
        }
    };
    check(
        "name,node_id,address,colour\nx1,nsu=urn:plc;s=X1,X1\n",
        &["base/tags.csv:1:1: tags_file: unknown column 'colour'"],
    );
    check(
        "name,address\nx1,X1\n",
        &["base/tags.csv:1:1: tags_file: the header row has no 'node_id' column"],
    );
    check(
        "name,node_id,address,bit\nx1,nsu=urn:plc;s=X1,X1,\nx2,nsu=urn:plc;s=X2,X2,two\n",
        &["base/tags.csv:3:1: tags[1].bit: 'two' is not a number"],
    );
    check(
        "name,node_id,address\nx1,nsu=urn:plc;s=X1,X1\nx2,nsu=urn:plc;s=X2,X1\n",
        &["base/tags.csv:3:1: tags[1].address: X1 is used by another tag"],
    );
    check(
        "name,node_id,address\nx1,nsu=urn:plc;s=X1,X1\nx2,nsu=urn:plc;s=X2\n",
        &["base/tags.csv:3:1: tags_file: "],
    );
    check(
        "name,node_id,address\nx1,nsu=urn:plc;s=X1,X1\n\n# the second\n,nsu=urn:plc;s=X2,X2\n",
        &["base/tags.csv:5:1: tags[1].name: is empty"],
    );
    // The configuration's own problems still point into it.
    let (text, files) = with_tags_file("name,node_id,address\nx1,nsu=urn:plc;s=X1,X1\n");
    let e = parse("cell.toml", &text, Path::new("base"), &files)
        .unwrap_err()
        .to_string();
    assert!(e.contains("cell.toml:") && e.contains("X2"), "{e}");
    // Both at once, and a file that is not there.
    let (text, files) =
        with_tags_file("name,node_id,address\nx1,nsu=urn:plc;s=X1,X1\nx2,nsu=urn:plc;s=X2,X2\n");
    let both = format!(
        "{text}\n[[tags]]\nname = \"x3\"\nnode_id = \"nsu=urn:plc;s=X3\"\naddress = \"X3\"\n"
    );
    let e = parse("cell.toml", &both, Path::new("base"), &files)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(
            "cell.toml:1:13: tags_file: give the tags as [[tags]] tables or in tags_file, not both"
        ),
        "{e}"
    );
    let e = parse("cell.toml", &text, Path::new("base"), &mem())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cell.toml:1:13: tags_file: cannot read the tags file 'base/tags.csv'"),
        "{e}"
    );
}

/// An S7 cell: an STL program with a block's own local, tags written as
/// STL addresses.
const STL_CELL: &str = r#"
[cell]
id = "s7"
dialect = "stl"

[opcua]
endpoint = "opc.tcp://127.0.0.1:4840/"

[[tags]]
name = "start"
node_id = "ns=3;s=\"Eingaenge\".Start"
address = "E 0.0"

[[tags]]
name = "stop"
node_id = "ns=3;s=\"Eingaenge\".Stop"
address = "e0.1"

[[tags]]
name = "reset"
node_id = "ns=3;s=\"DB_Band\".Reset"
address = "\"Band\".#Reset"

[[tags]]
name = "level"
node_id = "ns=3;s=\"Daten\".Fuellstand"
address = "MW 10"
type = "Int16"

[[checks.switching]]
id = "band"
program = "band.awl"
coil = "A 4.0"
observable = "E,A,Band.#Reset"
armed_when = "MW10 > 5"

[zenoh.tls]
ca = "pki-bus/ca.pem"
cert = "pki-bus/agent-s7.pem"
key = "pki-bus/agent-s7.key"
"#;

fn stl_files() -> Mem {
    let mut m = mem();
    m.0.insert(
        PathBuf::from("base/band.awl"),
        "FUNCTION_BLOCK \"Band\"\nVAR\n  Reset : BOOL ; // Band zurücksetzen\nEND_VAR\nBEGIN\n\
         NETWORK\nU E 0.0\nUN E 0.1\n= #Reset\nEND_FUNCTION_BLOCK\n\
         FUNCTION FC 1 : VOID\nVAR_TEMP\n  Reset : BOOL ;\nEND_VAR\nBEGIN\n\
         NETWORK\nU \"Band\".#Reset\n= #Reset\nU #Reset\n= A 4.0\nEND_FUNCTION\n"
            .as_bytes()
            .to_vec(),
    );
    m
}

#[test]
fn an_s7_cell_reads_its_tags_as_stl_addresses() {
    let c = parse("cell.toml", STL_CELL, Path::new("base"), &stl_files()).unwrap();
    assert_eq!(c.addressing, Addressing::In(Dialect::Stl));
    let addresses: Vec<&str> = c.tags.iter().map(|t| t.address.name()).collect();
    assert_eq!(addresses, ["E0.0", "E0.1", "Band.#Reset", "MW10"]);
    let check = &c.switching[0];
    // FC1's own `#Reset` is expanded; the block Band's is a leaf, a tag.
    assert_eq!(check.sf.notation(), "Band.#Reset");
    assert_eq!(
        check.comments.get(&Signal::new("Band.#Reset")),
        Some("Band zurücksetzen")
    );
    let armed = check.armed_when.as_ref().unwrap();
    assert_eq!(
        armed
            .leaves()
            .into_iter()
            .map(|s| s.name().to_string())
            .collect::<Vec<_>>(),
        ["MW10 > 5"]
    );
}

#[test]
fn an_stl_program_over_pmc_addresses_says_which_key_fixes_it() {
    let text = STL_CELL
        .replace("dialect = \"stl\"\n", "")
        .replace("address = \"E 0.0\"", "address = \"E0.0\"")
        .replace("address = \"\\\"Band\\\".#Reset\"", "address = \"Reset\"")
        .replace("address = \"MW 10\"", "address = \"MW10\"")
        .replace("observable = \"E,A,Band.#Reset\"\n", "")
        .replace("armed_when = \"MW10 > 5\"\n", "");
    let e = parse("cell.toml", &text, Path::new("base"), &stl_files())
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        "cell.toml:32:8: checks.switching[0].coil: A4.0 reads E0.0, but no tag has that address; \
         add a [[tags]] entry for it (the program is stl: set cell.dialect = \"stl\" to read the \
         tags' addresses as it writes them)\n\
         cell.toml:32:8: checks.switching[0].coil: A4.0 reads E0.1, but no tag has that address; \
         add a [[tags]] entry for it (the program is stl: set cell.dialect = \"stl\" to read the \
         tags' addresses as it writes them)"
    );
    let bad = STL_CELL.replace("dialect = \"stl\"", "dialect = \"s7\"");
    assert!(errors(&bad)
        .starts_with("cell.toml:4:11: cell.dialect: unknown dialect 's7': use pmc, iec or stl"));
    let bad = STL_CELL.replace("address = \"E 0.0\"", "address = \"E 0.9\"");
    assert!(errors(&bad).contains(
        "tags[0].address: malformed address 'E 0.9': expected byte.bit with a bit 0..7, as in E 0.0"
    ));
}

#[test]
fn ids_that_make_alarm_ids_are_zenoh_key_chunks() {
    assert_eq!(
        errors(&GOOD.replace("id = \"fig6\"", "id = \"fig/6\"")),
        "cell.toml:19:6: checks.switching[0].id: 'fig/6' must be letters, digits, '-' or '_' (it is part of Zenoh keys)"
    );
    // A step's name is part of its stuck alarm's id (`sfc-F1-S1`).
    let (text, mut files) = robot_cell("");
    let charts =
        include_str!("../../../../config/robot/robot.sfc.toml").replace("\"S1\"", "\"S1\\n\"");
    files
        .0
        .insert(PathBuf::from("base/robot.sfc.toml"), charts.into_bytes());
    assert_eq!(
        parse("cell.toml", &text, Path::new("base"), &files)
            .unwrap_err()
            .to_string(),
        "cell.toml:139:10: checks.sfc[0].charts: chart F1 step 'S1\\n' must be letters, digits, '-' or '_' (it is part of Zenoh keys)"
    );
}

#[test]
fn a_shelf_limit_beyond_a_year_is_refused() {
    let text = format!("{GOOD}\n[commands]\nmax_shelve = \"1000000000y\"\n");
    let e = errors(&text);
    assert!(
        e.ends_with("commands.max_shelve: at most 365d: an alarm to be kept quiet longer is taken out of service"),
        "{e}"
    );
    let text = format!("{GOOD}\n[commands]\nmax_shelve = \"365d\"\n");
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    assert_eq!(c.max_shelve, Duration::from_secs(365 * 24 * 3600));
}

#[test]
fn a_limit_and_production_name_their_tag_by_name_or_address() {
    let text = typed(
        "[[checks.limit]]\nid = \"t\"\ntag = \"temp\"\nh = { limit = 80.0 }\n\n\
         [production]\ncounter = \"count\"\n",
    )
    .replace(
        "address = \"D1\"\ntype = \"Double\"",
        "address = \"D1\"\ntype = \"Double\"\ncomment = \"Spindle temperature\"",
    );
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    assert_eq!(c.limits[0].tag, Signal::new("D1"));
    assert_eq!(c.limits[0].label, "temp");
    assert_eq!(c.limits[0].comment.as_deref(), Some("Spindle temperature"));
    assert_eq!(c.part_counters, [3]);
    // A name that is another tag's address is ambiguous; a name no tag
    // has is said as such.
    let bad = typed(
        "[[checks.limit]]\nid = \"t\"\ntag = \"D2\"\nh = { limit = 80.0 }\n\n\
         [[checks.limit]]\nid = \"u\"\ntag = \"tmp\"\nh = { limit = 1.0 }\n",
    )
    .replace("name = \"temp\"", "name = \"D2\"");
    assert_eq!(
        errors(&bad),
        "cell.toml:43:7: checks.limit[0].tag: 'D2' is the name of the tag at D1 and the address of another tag: write the address you mean\n\
         cell.toml:48:7: checks.limit[1].tag: no tag is named 'tmp' or has the address tmp"
    );
}

#[test]
fn a_limits_hysteresis_is_not_the_tags_deadband() {
    let text = typed(
        "[[checks.limit]]\nid = \"t\"\ntag = \"D1\"\nhysteresis = 1.5\nh = { limit = 80.0 }\n",
    );
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    assert_eq!(c.limits[0].deadband, 1.5);
    assert!(
        c.warnings.iter().all(|w| !w.contains("hysteresis")),
        "{:?}",
        c.warnings
    );
    // The former name: taken, and said.
    let old =
        typed("[[checks.limit]]\nid = \"t\"\ntag = \"D1\"\ndeadband = 1.5\nh = { limit = 80.0 }\n");
    let c = parse("cell.toml", &old, Path::new("base"), &mem()).unwrap();
    assert_eq!(c.limits[0].deadband, 1.5);
    assert!(
        c.warnings.contains(&"checks.limit[0] (t): deadband is called hysteresis now (the deadband of [[tags]] is the server's change filter): rename it".to_string()),
        "{:?}",
        c.warnings
    );
    let both = typed("[[checks.limit]]\nid = \"t\"\ntag = \"D1\"\nhysteresis = 1.5\ndeadband = 1.5\nh = { limit = 80.0 }\n");
    assert_eq!(
        errors(&both),
        "cell.toml:45:12: checks.limit[0].deadband: give hysteresis only (deadband is its former name)"
    );
}

#[test]
fn a_discrete_alarm_is_a_switching_check_over_one_contact() {
    let text = typed(
        "[[checks.discrete]]\nid = \"door\"\ntag = \"x2\"\nfault_when = \"off\"\n\
         message = \"Guard door open\"\nseverity = \"critical\"\non_delay = \"2s\"\n\n\
         [[checks.discrete]]\nid = \"x1-on\"\ntag = \"X1\"\n",
    );
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    let door = c.switching.iter().find(|s| s.id == "door").unwrap();
    assert_eq!(door.text.as_deref(), Some("Guard door open"));
    assert_eq!(door.fault_type, "X2 OFF");
    assert_eq!(door.severity, Severity::Critical);
    assert_eq!(door.polarity, cellwatch_models::explain::Polarity::Off);
    assert_eq!(door.sf.leaves(), vec![Signal::new("X2")]);
    assert!(c.delays.contains(&("door".into(), 2000, 0)));
    // Defaults: on is the fault, high, the tag's name as the message
    // (it has no comment), no delay.
    let x1 = c.switching.iter().find(|s| s.id == "x1-on").unwrap();
    assert_eq!(
        (
            x1.text.as_deref(),
            x1.fault_type.as_str(),
            x1.severity,
            x1.polarity
        ),
        (
            Some("x1"),
            "X1 ON",
            Severity::High,
            cellwatch_models::explain::Polarity::On
        )
    );
    assert!(!c.delays.iter().any(|d| d.0 == "x1-on"));
}

#[test]
fn a_discrete_alarm_needs_a_contact_a_known_tag_and_its_own_id() {
    let bad = typed(
        "[[checks.discrete]]\nid = \"hot\"\ntag = \"temp\"\n\n\
         [[checks.discrete]]\nid = \"gone\"\ntag = \"x9\"\n\n\
         [[checks.discrete]]\nid = \"tag-quality\"\ntag = \"x1\"\n\n\
         [[checks.discrete]]\nid = \"fig6\"\ntag = \"x1\"\nmessage = \" \"\nfault_when = \"open\"\n",
    );
    let e = errors(&bad);
    for expected in [
        "checks.discrete[0].tag: D1 is a Double: a discrete alarm needs a Boolean tag or one bit of a word (bit = n); for a number use [[checks.limit]]",
        "checks.discrete[1].tag: no tag is named 'x9' or has the address X9",
        "checks.discrete[2].id: 'tag-quality' is the id of the agent's own alarm: choose another",
        "checks.discrete[3].id: 'fig6' is used twice",
        "checks.discrete[3].message: is empty: leave it out to use the tag's comment",
        "checks.discrete[3].fault_when: unknown polarity 'open': use on or off",
    ] {
        assert!(e.contains(expected), "{expected}\nin\n{e}");
    }
}

#[test]
fn kpi_rules_default_to_isa_18_2_and_are_checked() {
    let c = parse("cell.toml", GOOD, Path::new("base"), &mem()).unwrap();
    assert_eq!(c.kpi, cellwatch_models::kpi::KpiRules::default());
    assert_eq!((c.kpi.flood_raises, c.kpi.flood_ends_below), (10, 5));
    let own = format!(
        "{GOOD}\n[kpi]\nflood_raises = 20\nchatter_raises = 4\nchatter_window = \"2min\"\nstale_after = \"8h\"\n"
    );
    let c = parse("cell.toml", &own, Path::new("base"), &mem()).unwrap();
    assert_eq!(
        c.kpi,
        cellwatch_models::kpi::KpiRules {
            flood_raises: 20,
            flood_ends_below: 10,
            chatter_raises: 4,
            chatter_window_ms: 120_000,
            stale_ms: 8 * 3_600_000,
        }
    );
    let bad = format!(
        "{GOOD}\n[kpi]\nflood_raises = 0\nflood_ends_below = 12\nchatter_raises = 1\nchatter_window = \"2h\"\nstale_after = \"10s\"\n"
    );
    let e = errors(&bad);
    for expected in [
        "kpi.flood_raises: 0 is not between 1 and 10000",
        "kpi.flood_ends_below: 12 is not between 1 and 11 (flood_raises + 1: no hysteresis)",
        "kpi.chatter_raises: 1 is not between 2 and 100",
        "kpi.chatter_window: must be between 1s and 1h",
        "kpi.stale_after: must be between 1min and 366d",
    ] {
        assert!(e.contains(expected), "{expected}\nin\n{e}");
    }
}

#[test]
fn conditions_name_tags_by_name_or_address() {
    // x1 and x2 are the names of X1 and X2; temp of the Double D1.
    let text = typed(
        "[state]\nrunning = \"x1 * -X2 * temp < 80\"\n\n\
         [[checks.discrete]]\nid = \"x2-on\"\ntag = \"x2\"\narmed_when = \"x1 + count > 3\"\n",
    );
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    let running = c.state.running.as_ref().unwrap().to_string();
    assert!(
        running.contains("X1") && running.contains("D1 < 80") && !running.contains("x1"),
        "{running}"
    );
    let armed = c.switching.iter().find(|s| s.id == "x2-on").unwrap();
    let armed = armed.armed_when.as_ref().unwrap().notation();
    assert!(armed.contains("X1") && armed.contains("D2 > 3"), "{armed}");
    // A name no tag has, and no address of one: said.
    let e = errors(&typed("[state]\nrunning = \"x1 * ghost\"\n"));
    assert!(
        e.contains("state.running: no tag has the name or address ghost"),
        "{e}"
    );
}
