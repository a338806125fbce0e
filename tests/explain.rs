//! `cellwatch explain`: the paper's ESE and CSD faults from the command line.

use crate::util::{cellwatch, Dir};

/// The example of `README.md` and `docs/reference/cli.md` (`cellwatch
/// explain`), as written there.
#[test]
fn readme_example_names_the_y_over_travel_switch() {
    let r = cellwatch(&[
        "explain",
        "config/cnc/ese.il",
        "--coil",
        "G8.02",
        "--snapshot",
        "config/cnc/ese-y-overtravel.values",
        "--before",
        "config/cnc/ese-normal.values",
        "--comments",
        "config/cnc/ese-comments.csv",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .starts_with("G8.02 = 1: FAULT (fault when on), at step 6\n"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout.ends_with(
            "culprits:\n  X0.06 = 0 (expected 1): Y Over Travel Limit SW (B)   [trigger]\n"
        ),
        "{}",
        r.stdout
    );
}

#[test]
fn csd_json_with_inline_values() {
    let d = Dir::new();
    let snapshot = d.file(
        "jog.csv",
        "address,value\nF17.00,1\nF17.01,1\nF17.02,1\nF17.03,1\nF18.00,1\nF18.01,1\nF18.02,1\nF18.03,1\n\
         R35.00,1\nG0.00,1\nR0.00,1\nX0.0D,1\nX0.0E,1\nX201.02,0\nX201.03,0\nX201.06,1\nX200.01,1\n",
    );
    let r = cellwatch(&[
        "explain",
        "config/cnc/csd.il",
        "--coil",
        "G9.00",
        "--snapshot",
        &snapshot,
        "--before",
        "X200.01=0",
        "--comments",
        "config/cnc/csd-comments.csv",
        "--json",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(v["coil"], "G9.00");
    assert_eq!(v["value"], true);
    assert_eq!(v["fault_step"], 3);
    assert_eq!(v["steps"].as_array().unwrap().len(), 9);
    assert_eq!(
        v["steps"][2],
        serde_json::json!({"index": 3, "value": true, "expr": "X200.01 * X201.06"})
    );
    let first = &v["culprits"][0];
    assert_eq!(
        first,
        &serde_json::json!({"address": "X200.01", "value": true, "expected": false, "comment": "Cycle Start", "trigger": true})
    );
    let addresses: Vec<&str> = v["culprits"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["address"].as_str().unwrap())
        .collect();
    assert!(addresses.contains(&"X201.06"), "{addresses:?}");
}

#[test]
fn no_fault_is_said_plainly() {
    let r = cellwatch(&[
        "explain",
        "config/cnc/ese.il",
        "--coil",
        "G8.02",
        "--snapshot",
        "config/cnc/ese-normal.values",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .starts_with("G8.02 = 0: no fault (fault when on)\n"),
        "{}",
        r.stdout
    );
    assert!(!r.stdout.contains("culprits"));
}

#[test]
fn enable_coil_faults_when_off() {
    let d = Dir::new();
    let p = d.file("enable.il", "RD X1\nAND X2\nAND.NOT X3\nWRT G9.00\n");
    let r = cellwatch(&[
        "explain",
        &p,
        "--coil",
        "G9.00",
        "--snapshot",
        "X1=1,X2=0,X3=1",
        "--fault-when",
        "off",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .contains("G9.00 = 0: FAULT (fault when off), at step 1\n"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout
            .ends_with("culprits:\n  X2 = 0 (expected 1)\n  X3 = 1 (expected 0)\n"),
        "{}",
        r.stdout
    );
}

#[test]
fn a_studio_5000_export_is_explained_as_its_instruction_list_is() {
    // Fig. 6 as Logix Designer exports it: the alarm lamp Y2 lit disables
    // cycle start at the last step block, the lamp to blame.
    let r = cellwatch(&[
        "explain",
        "tests/data/paper000/fig6.L5X",
        "--coil",
        "G0_00",
        "--snapshot",
        "X1=1,X2=0,X3=1,Y1=0,X4=1,Y2=1",
        "--before",
        "X1=1,X2=0,X3=1,Y1=0,X4=1,Y2=0",
        "--fault-when",
        "off",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .starts_with("G0_00 = 0: FAULT (fault when off), at step 4\n"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout
            .ends_with("culprits:\n  Y2 = 1 (expected 0): Y2: axis alarm lamp   [trigger]\n"),
        "{}",
        r.stdout
    );
}

/// `explain --consequences` on paper 000's machine with the emergency-stop
/// coil a contact of the cycle-start logic (`tests/data/paper000/csd-ese.il`):
/// the relation an engineer reviews, pinned; and the paper's own programs,
/// where ESE and CSD stay independent.
#[test]
fn the_consequence_relation_is_printed_for_review() {
    let root = crate::util::root();
    let d = Dir::new();
    let mut signals: Vec<String> = Vec::new();
    for values in [
        "config/cnc/ese-normal.values",
        "config/cnc/csd-normal.values",
    ] {
        for line in std::fs::read_to_string(root.join(values)).unwrap().lines() {
            if let Some((a, _)) = line.split_once(',').filter(|_| !line.starts_with('#')) {
                if a != "address" && !signals.iter().any(|s| s == a) {
                    signals.push(a.to_string());
                }
            }
        }
    }
    signals.push("G8.02".into());
    let config = |csd: &str| {
        let mut t = String::from(
            "[cell]\nid = \"m01\"\n\n[opcua]\nendpoint = \"opc.tcp://127.0.0.1:4840/\"\n\n\
             [zenoh.tls]\nca = \"ca.pem\"\ncert = \"agent.pem\"\nkey = \"agent.key\"\n\n",
        );
        for s in &signals {
            t += &format!(
                "[[tags]]\nname = \"{}\"\nnode_id = \"ns=2;s={s}\"\naddress = \"{s}\"\n\n",
                s.replace('.', "_").to_lowercase()
            );
        }
        t += &format!(
            "[[checks.switching]]\nid = \"ese\"\nprogram = \"{}\"\ncoil = \"G8.02\"\n\n\
             [[checks.switching]]\nid = \"csd\"\nprogram = \"{}\"\ncoil = \"G9.00\"\narmed_when = \"X200.01\"\n",
            root.join("config/cnc/ese.il").display(),
            root.join(csd).display()
        );
        t
    };
    let related = d.file("related.toml", config("tests/data/paper000/csd-ese.il"));
    let r = cellwatch(&["explain", "--consequences", &related]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(
        r.stdout,
        "cell m01: consequences annunciated, each marked with its cause (alarms.consequences.suppress = false)\n\
         ese -> csd   csd reads G8.02, which ese's fault holds\n\
         communication -> every alarm raised while the link is down\n\
         tag-quality -> an alarm whose culprits are all tags of bad quality\n"
    );
    let independent = d.file("independent.toml", config("config/cnc/csd.il"));
    let r = cellwatch(&["explain", "--consequences", &independent]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .contains("\nno alarm of the cell's checks follows from another\n"),
        "{}",
        r.stdout
    );
    // A configuration that does not compile: bad input, said.
    let bad = d.file(
        "bad.toml",
        config("config/cnc/csd.il")
            + "\n[alarms.consequences]\nremove = [{ cause = \"ese\", effect = \"csd\" }]\n",
    );
    let r = cellwatch(&["explain", "--consequences", &bad]);
    assert_eq!(r.code, 2, "{}", r.stdout);
    assert!(
        r.stderr
            .contains("alarms.consequences.remove[0]: ese -> csd is no edge"),
        "{}",
        r.stderr
    );
}
