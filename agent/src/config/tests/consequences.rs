//! Configuration tests of `[alarms.consequences]`: the relation the checks
//! give (a fault coil read by another check, a forced output), edges added
//! and removed, and the errors that name the bad edge.

use super::*;

/// GOOD, plus: fig6's program also drives the lamp Y1.00 from its coil
/// G0.00 (a forced output); check `start` reads G0.00, check `lamp` reads
/// Y1.00, check `other` reads neither.
fn cascade(extra: &str) -> (String, Mem) {
    let mut files = mem();
    files.0.insert(
        PathBuf::from("base/fig6.il"),
        b"RD X1\nANDN X2\nWRT G0.00\nRD G0.00\nWRT Y1.00\n".to_vec(),
    );
    files.0.insert(
        PathBuf::from("base/start.il"),
        b"RD X2\nOR G0.00\nWRT G1.00\nRD X1\nOR Y1.00\nWRT G2.00\nRD X1\nAND X2\nWRT G3.00\n"
            .to_vec(),
    );
    let mut text = GOOD.replace("[zenoh.tls]", &format!("{}\n[zenoh.tls]", extra_checks()));
    text.push_str(extra);
    (text, files)
}

fn extra_checks() -> String {
    let mut s = String::new();
    for (addr, name) in [("G0.00", "g0"), ("Y1.00", "y1")] {
        s += &format!("[[tags]]\nname = \"{name}\"\nnode_id = \"nsu=urn:plc;s={addr}\"\naddress = \"{addr}\"\n\n");
    }
    for (id, coil) in [("start", "G1.00"), ("lamp", "G2.00"), ("other", "G3.00")] {
        s += &format!(
            "[[checks.switching]]\nid = \"{id}\"\nprogram = \"start.il\"\ncoil = \"{coil}\"\n\n"
        );
    }
    s
}

fn relation(text: &str, files: &Mem) -> Result<String, String> {
    let c = parse("cell.toml", text, Path::new("base"), files).map_err(|e| e.to_string())?;
    crate::cell::compile::engine(&c)
        .map(|e| e.relation().render())
        .map_err(|e| e.to_string())
}

#[test]
fn a_coil_read_by_another_check_and_its_forced_outputs_relate_the_alarms() {
    let (text, files) = cascade("");
    let c = parse("cell.toml", &text, Path::new("base"), &files).unwrap();
    let forced: Vec<&Signal> = c.switching[0].forces.iter().map(|f| &f.coil).collect();
    assert_eq!(forced, [&Signal::new("Y1.00")]);
    assert!(!c.consequences.suppress);
    assert_eq!(
        relation(&text, &files).unwrap(),
        "fig6 -> lamp    lamp reads Y1.00, which fig6's fault holds\n\
         fig6 -> start   start reads G0.00, which fig6's fault holds\n\
         communication -> every alarm raised while the link is down\n\
         tag-quality -> an alarm whose culprits are all tags of bad quality\n"
    );
}

#[test]
fn edges_are_added_and_removed_by_the_configuration() {
    let (text, files) = cascade(
        "\n[alarms.consequences]\nsuppress = true\n\
         add = [{ cause = \"start\", effect = \"other\" }]\n\
         remove = [{ cause = \"fig6\", effect = \"lamp\" }]\n",
    );
    let c = parse("cell.toml", &text, Path::new("base"), &files).unwrap();
    assert!(c.consequences.suppress);
    assert_eq!(
        relation(&text, &files).unwrap(),
        "fig6 -> start    start reads G0.00, which fig6's fault holds\n\
         start -> other   written in the configuration\n\
         communication -> every alarm raised while the link is down\n\
         tag-quality -> an alarm whose culprits are all tags of bad quality\n"
    );
}

#[test]
fn an_edge_may_name_an_alarm_of_the_plcs_own() {
    let (text, files) = cascade(
        "\n[[opcua.events]]\n\n[alarms.consequences]\n\
         add = [{ cause = \"fig6\", effect = \"plc-Press-Guard\" }]\n",
    );
    assert!(relation(&text, &files)
        .unwrap()
        .contains("fig6 -> plc-Press-Guard   written in the configuration"));
}

#[test]
fn a_bad_edge_is_named_with_its_key() {
    let (text, files) =
        cascade("\n[alarms.consequences]\nadd = [{ cause = \"fig7\", effect = \"start\" }]\n");
    assert_eq!(
        relation(&text, &files).unwrap_err(),
        "alarms.consequences.add[0]: 'fig7' is no alarm of this cell's checks or of the PLC's (`[[opcua.events]]` prefixes)"
    );
    // The PLC's own alarms only when the cell takes them.
    let plc =
        "\n[alarms.consequences]\nadd = [{ cause = \"fig6\", effect = \"plc-Press-Guard\" }]\n";
    let (text, files) = cascade(plc);
    assert!(relation(&text, &files)
        .unwrap_err()
        .contains("'plc-Press-Guard' is no alarm"));
    let (text, files) =
        cascade("\n[alarms.consequences]\nremove = [{ cause = \"start\", effect = \"fig6\" }]\n");
    assert_eq!(
        relation(&text, &files).unwrap_err(),
        "alarms.consequences.remove[0]: start -> fig6 is no edge of the relation the checks give (`cellwatch explain --consequences` prints it)"
    );
    let (text, files) =
        cascade("\n[alarms.consequences]\nadd = [{ cause = \"start\", effect = \"start\" }]\n");
    let e = parse("cell.toml", &text, Path::new("base"), &files)
        .unwrap_err()
        .to_string();
    assert!(
        e.ends_with("alarms.consequences.add[0]: 'start' cannot follow from itself"),
        "{e}"
    );
    assert!(e.starts_with("cell.toml:"), "{e}");
}

/// The clamp station of `tests/data/station`: its hydraulic fault and its
/// chart supervised, with `extra` in the chart's table.
fn station(extra: &str) -> (String, Mem) {
    let mut files = mem();
    files.0.insert(
        PathBuf::from("base/station.il"),
        include_bytes!("../../../../tests/data/station/station.il").to_vec(),
    );
    files.0.insert(
        PathBuf::from("base/station.sfc.toml"),
        include_bytes!("../../../../tests/data/station/station.sfc.toml").to_vec(),
    );
    let mut text = String::from(
        "[cell]\nid = \"c1\"\n\n[opcua]\nendpoint = \"opc.tcp://127.0.0.1:4840/\"\n\n",
    );
    for addr in [
        "X1.00", "X1.01", "X1.02", "X1.03", "X1.04", "X1.05", "R100.00", "R100.01", "R100.02",
        "Y2.00", "Y2.02", "Y3.00", "G10.00",
    ] {
        text += &format!(
            "[[tags]]\nname = \"{}\"\nnode_id = \"nsu=urn:plc;s={addr}\"\naddress = \"{addr}\"\n\n",
            addr.to_lowercase().replace('.', "_")
        );
    }
    text +=
        "[[checks.switching]]\nid = \"hydraulic\"\nprogram = \"station.il\"\ncoil = \"G10.00\"\n\n";
    text += &format!("[[checks.sfc]]\nid = \"sfc\"\ncharts = \"station.sfc.toml\"\n{extra}\n\n");
    text += "[zenoh.tls]\nca = \"pki-bus/ca.pem\"\ncert = \"pki-bus/agent-c1.pem\"\nkey = \"pki-bus/agent-c1.key\"\n";
    (text, files)
}

#[test]
fn the_program_of_a_chart_relates_a_stuck_step_to_the_fault_that_drops_its_valve() {
    // Without the program, the clamp step waits for the end switch only,
    // which the hydraulic fault does not hold: no edge.
    let (text, files) = station("");
    let without = relation(&text, &files).unwrap();
    assert!(!without.contains("hydraulic -> sfc-C1-S1"), "{without}");
    // With it, the step's flag drives the clamp valve, which the
    // hydraulic fault holds.
    let (text, files) = station("program = \"station.il\"");
    let with = relation(&text, &files).unwrap();
    let edge = with
        .lines()
        .find(|l| l.starts_with("hydraulic -> sfc-C1-S1 "))
        .unwrap_or_else(|| panic!("{with}"));
    assert!(edge.contains("Y2.00"), "{edge}");
}

#[test]
fn a_chart_program_that_drives_nothing_from_a_step_is_refused_at_its_key() {
    let (text, files) = station("program = \"fig6.il\"");
    let e = parse("cell.toml", &text, Path::new("base"), &files)
        .unwrap_err()
        .to_string();
    assert!(e.contains("checks.sfc[0].program"), "{e}");
    assert!(
        e.contains(
            "drives none of the cell's tags from a supervised step's flag (R100.01, R100.02)"
        ),
        "{e}"
    );
}
