//! Tests of the SimaticML reader: networks, calls, tag tables and what
//! is not read.

use crate::comments::CommentDb;
use crate::program::Program;
use crate::signal::{Observability, Signal};
use crate::switching::SwitchingFunction;

/// A block `Conveyor` with one network per `(language, parts, wires)`.
fn block(networks: &[(&str, &str, &str)]) -> String {
    let units: String = networks
        .iter()
        .enumerate()
        .map(|(i, (lang, parts, wires))| {
            let source = if *lang == "STL" {
                "<StatementList xmlns=\"http://www.siemens.com/automation/Openness/SW/NetworkSource/StatementList/v4\"/>".to_string()
            } else {
                format!(
                    "<FlgNet xmlns=\"http://www.siemens.com/automation/Openness/SW/NetworkSource/FlgNet/v{}\">\n<Parts>\n{parts}</Parts>\n<Wires>\n{wires}</Wires>\n</FlgNet>",
                    i % 5 + 1
                )
            };
            format!(
                "<SW.Blocks.CompileUnit ID=\"{i}\" CompositionName=\"CompileUnits\"><AttributeList><NetworkSource>{source}</NetworkSource>\n<ProgrammingLanguage>{lang}</ProgrammingLanguage></AttributeList></SW.Blocks.CompileUnit>\n"
            )
        })
        .collect();
    format!(
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<Document>\n<Engineering version=\"V18\" />\n<SW.Blocks.FB ID=\"0\"><AttributeList>\
         <Interface><Sections xmlns=\"http://www.siemens.com/automation/Openness/SW/Interface/v5\"><Section Name=\"Static\">\
         <Member Name=\"Busy\" Datatype=\"Bool\"><Comment><MultiLanguageText Lang=\"de-DE\">Belegt</MultiLanguageText></Comment></Member>\
         </Section></Sections></Interface><Name>Conveyor</Name><ProgrammingLanguage>LAD</ProgrammingLanguage></AttributeList>\n<ObjectList>\n{units}</ObjectList></SW.Blocks.FB>\n</Document>\n"
    )
}

fn tag(uid: u32, name: &str) -> String {
    format!("<Access Scope=\"GlobalVariable\" UId=\"{uid}\"><Symbol><Component Name=\"{name}\"/></Symbol></Access>\n")
}

fn local(uid: u32, name: &str) -> String {
    format!("<Access Scope=\"LocalVariable\" UId=\"{uid}\"><Symbol><Component Name=\"{name}\"/></Symbol></Access>\n")
}

fn number(uid: u32, value: &str) -> String {
    format!("<Access Scope=\"LiteralConstant\" UId=\"{uid}\"><Constant><ConstantType>Int</ConstantType><ConstantValue>{value}</ConstantValue></Constant></Access>\n")
}

fn part(uid: u32, name: &str, inner: &str) -> String {
    format!("<Part Name=\"{name}\" UId=\"{uid}\">{inner}</Part>\n")
}

/// A wire: `rail`, an operand's UId, or `UId.pin`.
fn wire(ends: &[&str]) -> String {
    let ends: String = ends
        .iter()
        .map(|e| match e.split_once('.') {
            _ if *e == "rail" => "<Powerrail/>".to_string(),
            Some((u, pin)) => format!("<NameCon UId=\"{u}\" Name=\"{pin}\"/>"),
            None => format!("<IdentCon UId=\"{e}\"/>"),
        })
        .collect();
    format!("<Wire UId=\"99\">{ends}</Wire>\n")
}

fn sf(p: &Program, coil: &str) -> String {
    SwitchingFunction::expand(
        p,
        &Signal::new(coil),
        &Observability::everything(p.dialect()),
    )
    .unwrap_or_else(|e| panic!("{e}"))
    .notation()
}

fn warnings(p: &Program) -> Vec<String> {
    p.warnings()
        .iter()
        .map(|w| format!("{}: {}", w.at, w.message))
        .collect()
}

/// A call of FB `Motor` with `instance` (an `Instance` element), its
/// Bool input `Start` and outputs `Running` and `Fault`, a number
/// `Speed`.
fn call(uid: u32, instance: &str) -> String {
    format!(
        "<Call UId=\"{uid}\"><CallInfo Name=\"Motor\" BlockType=\"FB\">{instance}\
         <Parameter Name=\"Start\" Section=\"Input\" Type=\"Bool\"/>\
         <Parameter Name=\"Running\" Section=\"Output\" Type=\"Bool\"/>\
         <Parameter Name=\"Fault\" Section=\"Output\" Type=\"Bool\"/>\
         <Parameter Name=\"Speed\" Section=\"Output\" Type=\"Int\"/></CallInfo></Call>\n"
    )
}

#[test]
fn outputs_of_function_block_calls_are_leaves_named_with_their_instance() {
    let global =
        "<Instance Scope=\"GlobalVariable\" UId=\"40\"><Component Name=\"Motor_DB\"/></Instance>";
    let multi =
        "<Instance Scope=\"LocalVariable\" UId=\"40\"><Component Name=\"Pump\"/></Instance>";
    // 1: the call, its outputs wired to operands (`Fault` into a
    // global tag) and straight into an AND box with a contact.
    let direct = tag(21, "Go")
        + &call(22, global)
        + &tag(23, "Motor_Fault")
        + &part(24, "A", "")
        + &tag(25, "Guard")
        + &part(26, "Coil", "")
        + &tag(27, "Ready");
    let direct_wires = wire(&["rail", "22.en"])
        + &wire(&["21", "22.Start"])
        + &wire(&["22.Fault", "23"])
        + &wire(&["22.Running", "24.in1"])
        + &wire(&["25", "24.in2"])
        + &wire(&["24.out", "26.in"])
        + &wire(&["27", "26.operand"]);
    // 2: a contact on `"Motor_DB".Fault` and one on a multi-instance's
    // `#Pump.Running`, into an alarm coil.
    let contacts = "<Access Scope=\"GlobalVariable\" UId=\"21\"><Symbol><Component Name=\"Motor_DB\"/><Component Name=\"Fault\"/></Symbol></Access>\n".to_string()
        + "<Access Scope=\"LocalVariable\" UId=\"22\"><Symbol><Component Name=\"Pump\"/><Component Name=\"Running\"/></Symbol></Access>\n"
        + &part(23, "Contact", "")
        + &part(24, "Contact", "<Negated Name=\"operand\"/>")
        + &part(25, "Coil", "")
        + &tag(26, "Alarm");
    let contact_wires = wire(&["rail", "23.in"])
        + &wire(&["21", "23.operand"])
        + &wire(&["23.out", "24.in"])
        + &wire(&["22", "24.operand"])
        + &wire(&["24.out", "25.in"])
        + &wire(&["26", "25.operand"]);
    // 3: the multi-instance called only while Go is on; its output
    // into a local. A number output into logic is not a bit.
    let guarded = tag(21, "Go")
        + &part(22, "Contact", "")
        + &call(23, multi)
        + &local(24, "PumpOn")
        + &part(25, "Coil", "")
        + &tag(26, "Fast");
    let guarded_wires = wire(&["rail", "22.in"])
        + &wire(&["21", "22.operand"])
        + &wire(&["22.out", "23.en"])
        + &wire(&["23.Running", "24"])
        + &wire(&["23.Speed", "25.in"])
        + &wire(&["26", "25.operand"]);
    let text = block(&[
        ("FBD", &direct, &direct_wires),
        ("LAD", &contacts, &contact_wires),
        ("LAD", &guarded, &guarded_wires),
    ]);
    let p = Program::compile("c.xml", &text, None).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(sf(&p, "Ready"), "Motor_DB.Running * Guard");
    assert_eq!(sf(&p, "Motor_Fault"), "Motor_DB.Fault");
    assert_eq!(sf(&p, "Alarm"), "Motor_DB.Fault * -Conveyor.#Pump.Running");
    let pump_on = SwitchingFunction::expand(
        &p,
        &Signal::new("Conveyor.#PumpOn"),
        &Observability::everything(p.dialect()),
    );
    assert!(
        pump_on
            .as_ref()
            .is_err_and(|e| e.to_string().contains("runs only while its 'en' is on")),
        "{pump_on:?}"
    );
    let fast = SwitchingFunction::expand(
        &p,
        &Signal::new("Fast"),
        &Observability::everything(p.dialect()),
    );
    assert!(
        fast.as_ref().is_err_and(|e| e
            .to_string()
            .contains("output 'Speed' of call of Motor is a Int, not a bit")),
        "{fast:?}"
    );
    // A fault through the call's output names the instance's member.
    let ready = SwitchingFunction::expand(
        &p,
        &Signal::new("Ready"),
        &Observability::everything(p.dialect()),
    )
    .unwrap();
    let mut now = crate::values::Values::new();
    now.set(Signal::new("Motor_DB.Running"), false);
    now.set(Signal::new("Guard"), true);
    let e = crate::explain::explain(
        &ready,
        |s| now.get(s),
        None,
        crate::explain::Polarity::Off,
        &CommentDb::default(),
    )
    .unwrap();
    let culprits: Vec<String> = e.culprits.iter().map(ToString::to_string).collect();
    assert_eq!(culprits, ["Motor_DB.Running = 0 (expected 1)"]);
}

#[test]
fn latches_timers_comparators_locals_and_edges() {
    // 1: Sr latch of Run (reset wins), Rs of Hold (set wins).
    let latch = tag(21, "Start")
        + &tag(22, "Stop")
        + &tag(23, "Run")
        + &part(24, "Contact", "")
        + &part(25, "Contact", "")
        + &part(26, "Sr", "")
        + &part(27, "Rs", "")
        + &tag(28, "Hold")
        + &part(29, "Coil", "")
        + &tag(30, "Running");
    let latch_wires = wire(&["rail", "24.in", "25.in"])
        + &wire(&["21", "24.operand"])
        + &wire(&["22", "25.operand"])
        + &wire(&["24.out", "26.s", "27.s1"])
        + &wire(&["25.out", "26.r1", "27.r"])
        + &wire(&["23", "26.operand"])
        + &wire(&["28", "27.operand"])
        + &wire(&["26.q", "29.in"])
        + &wire(&["30", "29.operand"]);
    // 2: a TON's Q in series with a comparison `Speed > 80`, into a
    // local; a negated coil.
    let timer = tag(21, "Speed")
        + &number(22, "80")
        + &part(
            23,
            "TON",
            "<Instance Scope=\"GlobalVariable\" UId=\"24\"><Component Name=\"T1_DB\"/></Instance>",
        )
        + &part(25, "Gt", "")
        + &local(26, "Busy")
        + &part(27, "Coil", "")
        + &part(28, "Coil", "<Negated Name=\"operand\"/>")
        + &tag(29, "Idle");
    let timer_wires = wire(&["rail", "23.IN"])
        + &wire(&["23.Q", "25.pre"])
        + &wire(&["21", "25.in1"])
        + &wire(&["22", "25.in2"])
        + &wire(&["25.out", "27.in", "28.in"])
        + &wire(&["26", "27.operand"])
        + &wire(&["29", "28.operand"]);
    // 3 (FBD): an edge into an AND box, and a box that is not read.
    let edge = tag(21, "Push")
        + &tag(22, "Pulse")
        + &part(23, "PBox", "")
        + &part(
            24,
            "A",
            "<TemplateValue Name=\"Card\" Type=\"Cardinality\">2</TemplateValue>",
        )
        + &part(25, "Coil", "")
        + &part(26, "Calc", "")
        + &tag(27, "Run")
        + &tag(28, "Mem");
    let edge_wires = wire(&["21", "23.in"])
        + &wire(&["28", "23.bit"])
        + &wire(&["23.out", "24.in1"])
        + &wire(&["27", "24.in2"])
        + &wire(&["24.out", "25.in"])
        + &wire(&["22", "25.operand"]);
    let text = block(&[
        ("LAD", &latch, &latch_wires),
        ("LAD", &timer, &timer_wires),
        ("FBD", &edge, &edge_wires),
        ("STL", "", ""),
    ]);
    let p = Program::compile("c.xml", &text, None).unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<&str> = p.coils().iter().map(|c| c.signal.name()).collect();
    assert_eq!(
        names,
        ["Run", "Hold", "Running", "Conveyor.#Busy", "Idle", "Pulse"]
    );
    assert_eq!(sf(&p, "Run"), "-Stop * (Start + Run)");
    assert_eq!(sf(&p, "Hold"), "Start + (-Stop * Hold)");
    assert_eq!(sf(&p, "Running"), "Run");
    assert_eq!(sf(&p, "Conveyor.#Busy"), "T1_DB.Q * Speed > 80");
    assert_eq!(sf(&p, "Idle"), "-(T1_DB.Q * Speed > 80)");
    assert!(p.coil(&Signal::new("Pulse")).unwrap().definition.is_err());
    assert_eq!(
        warnings(&p),
        [
            "58:1: 'block \"Conveyor\" network 3: edge 'PBox' on 'Mem' (a pulse, not a function of the signals)': a call, timer, counter, edge or function, not boolean logic: the coils it feeds are not derivable",
            "61:1: block \"Conveyor\" network 3: part 'Calc' is not read",
            "75:92: block \"Conveyor\" network 4: STL network not read (LAD and FBD networks are)",
        ]
    );
    // A local's comment: the only language there is.
    assert_eq!(
        p.documentation().get(&Signal::new("Conveyor.#Busy")),
        Some("Belegt")
    );
    assert_eq!(
        p.resolve("\"Conveyor\".#Busy").unwrap().name(),
        "Conveyor.#Busy"
    );
    assert_eq!(p.resolve("\"T1_DB\".Q").unwrap().name(), "T1_DB.Q");
    assert_eq!(p.resolve("%I0.0").unwrap().name(), "I0.0");
}

#[test]
fn bad_networks_are_refused_at_their_part() {
    let parts = tag(21, "Start")
        + &part(22, "Contact", "")
        + &part(23, "Coil", "")
        + &number(24, "5")
        + &part(25, "Coil", "")
        + &part(26, "Contact", "");
    let wires = wire(&["rail", "22.in", "26.in"])
        + &wire(&["21", "22.operand"])
        + &wire(&["22.out", "23.in"])
        + &wire(&["24", "23.operand"])
        + &wire(&["30.out", "25.in"])
        + &wire(&["21", "25.operand"]);
    let e = Program::compile("c.xml", &block(&[("LAD", &parts, &wires)]), None).unwrap_err();
    assert_eq!(
        e.to_string(),
        "c.xml:10:1: block \"Conveyor\" network 1: Coil on a constant\n\
         c.xml:20:16: block \"Conveyor\" network 1: wire 99 names part 30, which is not in this network"
    );
    let e = Program::compile(
        "t.xml",
        "<?xml version=\"1.0\"?>\n<Document>\n<SW.Blocks.FC>\n</Document>\n",
        None,
    )
    .unwrap_err();
    assert!(
        e.to_string().starts_with("t.xml:4:1: not well-formed XML"),
        "{e}"
    );
    let tags = "<?xml version=\"1.0\"?>\n<Document>\n  <SW.Tags.PlcTagTable ID=\"0\"><AttributeList><Name>IO</Name></AttributeList></SW.Tags.PlcTagTable>\n</Document>\n";
    let e = Program::compile("io.xml", tags, None).unwrap_err();
    assert_eq!(
        e.to_string(),
        "io.xml:3:3: this is a TIA Portal tag table, not a block: give it as the I/O list (--comments), and export the block (FC, FB or OB) to read its networks"
    );
    let e = Program::compile(
        "c.xml",
        &block(&[("STL", "", "")]),
        Some(crate::programs::Dialect::Stl),
    )
    .unwrap_err();
    assert_eq!(
        e.to_string(),
        "c.xml:1:1: this is a TIA Portal export (SimaticML), not an instruction list: leave --dialect out, and its LAD and FBD networks are read"
    );
    let e = CommentDb::parse("b.xml", &block(&[]), |a| {
        crate::programs::Dialect::Stl.signal(a)
    })
    .unwrap_err();
    assert_eq!(
        e.to_string(),
        "b.xml:2:1: this SimaticML document has no tag table (SW.Tags.PlcTagTable): export the PLC tag table, not a block"
    );
}

#[test]
fn german_addresses_in_english_mnemonics() {
    for (german, english) in [
        ("E0.0", Some("I0.0")),
        ("A4.1", Some("Q4.1")),
        ("EW10", Some("IW10")),
        ("AB2", Some("QB2")),
        ("PEW256", Some("PIW256")),
        ("PAD4", Some("PQD4")),
        ("Z3", Some("C3")),
        ("M10.1", None),
        ("MW10", None),
        ("T1", None),
        ("I0.0", None),
        ("Q4.0", None),
        ("DB1.DBX2.3", None),
        ("Alarm", None),
        ("EZ1", None),
    ] {
        assert_eq!(super::english(german).as_deref(), english, "{german}");
    }
}

#[test]
fn tag_tables_take_the_english_comment_and_the_project_s_mnemonics() {
    let item = |c: &str, t: &str| {
        format!("<MultilingualTextItem><AttributeList><Culture>{c}</Culture><Text>{t}</Text></AttributeList></MultilingualTextItem>")
    };
    let tag = |name: &str, address: &str, texts: &str| {
        format!(
            "<SW.Tags.PlcTag><AttributeList><LogicalAddress>{address}</LogicalAddress><Name>{name}</Name></AttributeList>\
             <ObjectList><MultilingualText CompositionName=\"Comment\"><ObjectList>{texts}</ObjectList></MultilingualText></ObjectList></SW.Tags.PlcTag>\n"
        )
    };
    let table = format!(
        "<?xml version=\"1.0\"?>\n<Document>\n<SW.Tags.PlcTagTable><ObjectList>\n{}{}{}{}</ObjectList></SW.Tags.PlcTagTable>\n</Document>\n",
        tag("Start", "%E0.0", &(item("de-DE", "Starttaster") + &item("en-US", "Start button"))),
        tag("Speed", "%MW10", &item("it-IT", "Velocità")),
        tag("Lamp", "%Q4.0", &(item("en-US", "") + &item("de-DE", "Lampe"))),
        tag("Bad", "%Q4.9", &item("en-US", "bad")),
    );
    let stl = |a: &str| crate::programs::Dialect::Stl.signal(a);
    let e = CommentDb::parse("io.xml", &table, stl);
    // The bit 4.9 is no address: the tag's name carries the comment.
    let db = e.unwrap();
    assert_eq!(db.get(&Signal::new("Start")), Some("Start button"));
    assert_eq!(db.get(&Signal::new("E0.0")), Some("Start button"));
    // A block's absolute operand is English: `%E0.0` is `I0.0` too.
    assert_eq!(db.get(&Signal::new("I0.0")), Some("Start button"));
    assert_eq!(db.get(&Signal::new("Speed")), Some("Velocità"));
    assert_eq!(db.get(&Signal::new("Lamp")), Some("Lampe"));
    assert_eq!(db.get(&Signal::new("Q4.0")), Some("Lampe"));
    assert_eq!(db.get(&Signal::new("Bad")), Some("bad"));
    assert_eq!(db.len(), 7);
    // In the language asked for, where a text has it; else the first.
    let de = CommentDb::parse_in("io.xml", &table, stl, Some("de-DE")).unwrap();
    assert_eq!(de.get(&Signal::new("Start")), Some("Starttaster"));
    assert_eq!(de.get(&Signal::new("Lamp")), Some("Lampe"));
    assert_eq!(de.get(&Signal::new("Speed")), Some("Velocità"));
    assert_eq!(de.get(&Signal::new("Bad")), Some("bad"));
    let pmc = CommentDb::parse("io.xml", &table, crate::signal::pmc_address).unwrap_err();
    assert_eq!(
        pmc.to_string(),
        "io.xml:4:1: malformed address '\"Start\"': it must start with a signal class letter (X, Y, R, F, G, ...)"
    );
}
