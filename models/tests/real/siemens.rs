//! Siemens programs: awlsim's STL sources and TIA Portal exports
//! (SimaticML), their latches and the networks they do not read.

use super::*;

// --- awlsim: Siemens STL -------------------------------------------------

#[test]
fn awlsim_garage_counter() {
    let p = program("awlsim-garagecounter.awl");
    pinned(
        &p,
        &[
            ("M4.0", "-((-E0.1 * -E0.2) + (-((-E0.1 * -E0.2) + M4.0) * ((-E0.1 * E0.2) + M4.1))) * ((E0.1 * -E0.2) + M4.0)"),
            ("A0.0", "-((-E0.1 * -E0.2) + (-((-E0.1 * -E0.2) + M4.0) * ((-E0.1 * E0.2) + M4.1))) * ((E0.1 * -E0.2) + M4.0) * -E0.1 * E0.2"),
            ("M4.1", "-((-E0.1 * -E0.2) + (-((-E0.1 * -E0.2) + M4.1) * ((E0.1 * -E0.2) + M4.0))) * ((-E0.1 * E0.2) + M4.1)"),
            ("A0.1", "-((-E0.1 * -E0.2) + (-((-E0.1 * -E0.2) + M4.1) * ((E0.1 * -E0.2) + M4.0))) * ((-E0.1 * E0.2) + M4.1) * E0.1 * -E0.2"),
            ("A0.2", "Z0"),
        ],
    );
    assert_eq!(p.warnings().len(), 17);
}

#[test]
fn awlsim_binary_divider() {
    let p = program("awlsim-binaeruntersetzer.awl");
    let got = outcome(&p);
    // b1_imp comes from an edge (FP); everything reading it is not
    // derivable, the set/reset latch MRUECK and the toggle M16.1 are.
    assert_eq!(got[0], ("b1_imp".into(), "! line 10".into()));
    assert_eq!(
        got[1],
        (
            "MRUECK".into(),
            "-(-A0 * -A1 * -A2) * ((A0 * A1 * A2) + MRUECK)".into()
        )
    );
    assert_eq!(
        got[9],
        ("M16.1".into(), "(T1 * -M16.1) + (-T1 * M16.1)".into())
    );
    assert_eq!(got.len(), 11);
    assert_eq!(got.iter().filter(|(_, s)| s.starts_with('!')).count(), 7);

    // By hand: S when A0·A1·A2, R when ¬A0·¬A1·¬A2, reset written last:
    // SSF1 = ¬A0·¬A1·¬A2, SSF2 = A0·A1·A2, SSF3 = SSF2 + MRUECK,
    // SSF4 = ¬SSF1·SSF3. All three outputs drop to 0 while MRUECK was on:
    // SSF1 = 1, so SSF4 = 0 — MRUECK is off (fault when off), the lowest
    // step on the fault's path is the reset condition SSF1, and each of A0,
    // A1, A2 at 0 (expected 1) is a cause.
    let before = values(&[("A0", true), ("A1", false), ("A2", false), ("MRUECK", true)]);
    let now = values(&[
        ("A0", false),
        ("A1", false),
        ("A2", false),
        ("MRUECK", true),
    ]);
    let e = explained(&p, "MRUECK", &before, &now, Polarity::Off);
    assert_eq!(e.steps, [true, false, true, false]);
    assert_eq!(e.fault_step, Some(1));
    assert_eq!(
        culprits(&e),
        [
            "A0 = 0 (expected 1)",
            "A1 = 0 (expected 1)",
            "A2 = 0 (expected 1)"
        ]
    );
    assert!(e.culprits[0].trigger && !e.culprits[1].trigger);
}

#[test]
fn awlsim_traffic_lights_and_step_chain() {
    let p = program("awlsim-trafficlights_1.awl");
    let got = outcome(&p);
    assert_eq!(
        got[1],
        (
            "M0.0".into(),
            "-(-T0 * M0.0) * ((-T0 * -M0.0 * E0.1) + M0.0)".into()
        )
    );
    // Outputs behind the jump list (SPL) at line 20 may not run every scan.
    assert!(got[2..].iter().all(|(_, s)| s == "! line 20"), "{got:?}");
    assert_eq!(got.len(), 7);
    assert_eq!(p.warnings().len(), 32);
    // The step chain counts in words: no boolean coil; its CALL parameter
    // list is skipped, not read as instructions.
    let p = program("awlsim-stepchain.awl");
    pinned(&p, &[]);
    assert_eq!(p.warnings().len(), 21);
    assert_eq!(
        p.documentation().get(&Signal::new("FB1.#SM")),
        Some("Schrittmerker")
    );
}

#[test]
fn awlsim_training_plant_export() {
    // A whole Step 7 export: several blocks, set/reset inside nesting
    // expressions, comparisons, indirect addressing.
    let p = program("awlsim-bnt_modell.awl");
    let got = outcome(&p);
    assert_eq!(got.len(), 169);
    assert_eq!(got.iter().filter(|(_, s)| !s.starts_with('!')).count(), 50);
    let find = |c: &str| got.iter().find(|(n, _)| n == c).map(|(_, s)| s.as_str());
    assert_eq!(
        find("Eingänge Schrittkette_3.#T14_15"),
        Some("(Eingänge Schrittkette_3.#Farbe_Rot * 4B4) + (-Eingänge Schrittkette_3.#Farbe_Rot * 4B5)")
    );
    assert_eq!(
        find("Betriebsarten.#STEU_EIN"),
        Some("-(-Betriebsarten.#STG_AUS + -Betriebsarten.#NOT_AUS) * (Betriebsarten.#STG_EIN + Betriebsarten.#STEU_EIN)")
    );
    assert_eq!(
        find("Programmzyklus.#TEMP_Aktor_vor"),
        Some("Handbetrieb * -AktorRück_Hand * AktorVor_Hand")
    );
    // Three blocks write a local `#T1_2` of their own: three coils, each
    // with its block's logic (read as one signal, the last block's write
    // hid the others').
    assert_eq!(
        find("Eingaenge_Schrittkette_1.#T1_2"),
        Some("1B3 * 1S2 * 1S2 * 2B5")
    );
    assert_eq!(find("Eingänge Schrittkette_3.#T1_2"), Some("4B6"));
    assert_eq!(got.iter().filter(|(n, _)| n.ends_with(".#T1_2")).count(), 3);
    assert_eq!(p.warnings().len(), 567);
}

// --- TIA Portal exports (SimaticML) ----------------------------------------

#[test]
fn tia_portal_exports_give_their_latches_and_say_which_networks_are_not_read() {
    // An FB in LAD: a valve opened by an S coil and closed by an R coil,
    // its state copied to an output. Locals are the block's own.
    let p = program("codegeneratoropenness-LAD_Valve_V0.1.xml");
    let latch = "-(Valve.#CloseValve * Valve.#Release) * ((Valve.#OpenValve * Valve.#Release) + Valve.#StateValve)";
    pinned(&p, &[("Valve.#StateValve", latch), ("Valve.#Valve", latch)]);
    assert!(warnings(&p).is_empty(), "{:?}", warnings(&p));
    // A contact on a global tag beside locals.
    let p = program("codegeneratoropenness-plcBlock_LAD_Block_Logic.xml");
    pinned(
        &p,
        &[
            ("Block_Logic.#MyValue", "Block_Logic.#A1"),
            ("Block_Logic.#Out1", "Block_Logic.#A1 * Tag_5"),
        ],
    );
    // Calls of an FB: said where they are, the coils around them read.
    let p = program("codegeneratoropenness-LAD_TemplateValve_V0.3.xml");
    pinned(
        &p,
        &[
            ("GenerateValve.#Release", "AlwaysOFF"),
            ("GenerateValve.#OpenValve", "AlwaysON * AlwaysOFF"),
            ("GenerateValve.#CloseValve", "AlwaysON * AlwaysOFF"),
            // Both calls write their output Valve into Valve_0: the last
            // one's instance member.
            ("Valve_0", "GenerateValve.#Valve_Instance_1.Valve"),
        ],
    );
    assert_eq!(
        warnings(&p),
        [
            "296:5: block \"GenerateValve\" network 3: call of Valve is not read",
            "578:5: block \"GenerateValve\" network 6: call of Valve is not read",
        ]
    );
    // A GRAPH sequence: no coil, one located warning per network.
    let p = program("codegeneratoropenness-GraphBranch.xml");
    pinned(&p, &[]);
    assert_eq!(
        warnings(&p),
        ["723:13: block \"FB_SEQ_One\" network 1: GRAPH network not read (LAD and FBD networks are)"]
    );
}

#[test]
fn tia_portal_exports_of_other_projects() {
    // A V21 LAD FC of a pump starter (Portuguese names): global tags with
    // hyphens, members of a DB whose name has a space, R coils without an
    // S coil, a negated coil, two empty networks (comments only). Calls of
    // FBs and MOVEs are said where they are; what they write reads as inputs.
    let p = program("tia-portal-cli-BombaTemplateFc.xml");
    let motor = "DB GLOBAL.AREA_01.AREA_01_MOTORES.MOTOR_S-01A";
    // The FB calls' Bool outputs are written into the tags wired to them,
    // each the instance's member: a leaf named with the instance (#69).
    let falha = "FB FALHA_S-01A";
    let partida = "FB CONDIÇÃO DE PARTIDA_S-01A";
    let reset_liga = format!("({partida}.RESET_CMD_LIGA + -CCM-1_STS_PAINEL_OK)");
    pinned(
        &p,
        &[
            ("S-01A_STS_MODO_LOCAL", "S-01A_STS_MOTOR_MODO_LOCAL_1"),
            ("S-01A_STS_MODO_REMOTO", "S-01A_STS_MOTOR_MODO_REMOTO_1"),
            ("S-01A_CMD_BOTAO_RESET_FALHA", "QA-01_CMD_RESET_REMOTA"),
            ("S-01A_FALHA", &format!("{falha}.FALHA")),
            (
                "S-01A_CMD_RESET_FALHA_PROFINET",
                &format!("{falha}.RESET_FALHA_INVERSOR"),
            ),
            (
                "S-01A_STS_FALHA_NAO_LIGOU",
                &format!("{falha}.FALHA_NÃO_LIGOU"),
            ),
            ("S-01A_CMD_LIGA_BOMBA", &format!("{partida}.LIGA_BOMBA")),
            (
                "S-01A_STS_REMOTO_AUTO",
                &format!("{partida}.OUTPUT_REMOTO_AUTO"),
            ),
            ("S-01A_CMD_RESET_LIGA", &format!("{partida}.RESET_CMD_LIGA")),
            (
                &format!("{motor}.STS_INTERTRAVAMENTO_AUTOMATICO"),
                &format!("{partida}.STS_INTERTRAVAMENTO_AUTOMATICO"),
            ),
            // Network 7's OR box feeds both coils below: one relay, as
            // the IL writes an internal relay (issue #69). Their
            // functions are what they were when the box was read twice.
            (
                "#PARTIDA_MOTOR_1 (S-01A).NW7.O28",
                &format!("{partida}.RESET_CMD_LIGA + -CCM-1_STS_PAINEL_OK"),
            ),
            (
                &format!("{motor}.CMD_LIGA"),
                &format!("-(S-01A_STS_MOTOR_MODO_LOCAL_1 + -S-01A_STS_MOTOR_MODO_REMOTO_1) * -{reset_liga} * {motor}.CMD_LIGA"),
            ),
            (
                &format!("{motor}.CMD_MODO_OPERACAO"),
                &format!("-({reset_liga} * {partida}.OUTPUT_REMOTO_AUTO) * {motor}.CMD_MODO_OPERACAO"),
            ),
            (
                &format!("{motor}.CMD_INTERTRAVAMENTO_LIGA"),
                &format!("-(-S-01A_STS_MOTOR_MODO_LOCAL_1 * -S-01A_STS_LOCAL_AUTO * -S-01A_STS_LOCAL_MANUAL * S-01A_STS_MOTOR_MODO_REMOTO_1 * S-01A_STS_REMOTO_MANUAL * -{falha}.FALHA)"),
            ),
            (
                "S-01A_STS_LIGADO_PROFINET",
                "SINA_SPEED_TLG20_S-01A.axisEnabled",
            ),
            ("S-01A_STS_FALHA_PROFINET", "SINA_SPEED_TLG20_S-01A.error"),
            ("S-01A_CMD_LIGA_PROFINET", &format!("{partida}.LIGA_BOMBA")),
        ],
    );
    let block = "block \"PARTIDA_MOTOR_1 (S-01A)\"";
    assert_eq!(
        warnings(&p),
        [
            format!("349:17: {block} network 2: call of FB FALHA is not read"),
            format!("724:17: {block} network 5: call of FB CONDIÇÃO DE PARTIDA is not read"),
            format!("1022:17: {block} network 6: part 'Move' is not read"),
            format!("1025:17: {block} network 6: part 'Move' is not read"),
            format!("1028:17: {block} network 6: call of FB SETPOINT ESCALONAMENTO is not read"),
            format!("1706:17: {block} network 10: call of SINA_SPEED_TLG20 is not read"),
        ]
    );

    // A V16 FBD FB stepping a sequence: every S coil is fed by a call's
    // ENO, every coil by a comparison of a local of a block whose name has
    // a space ("Program Logic"), which a comparison signal cannot carry:
    // no coil derivable, each saying where.
    let p = program("tia-xml-modcheck-Program_Logic.xml");
    pinned(
        &p,
        &[
            ("Program Logic.#StepDone", "! line 2037"),
            ("DB_ProgramLogic.VlvDrn_Open", "! line 2285"),
            ("DB_ProgramLogic.VlvLiq1_Open", "! line 2298"),
            ("DB_ProgramLogic.VlvLiq2_Open", "! line 2302"),
        ],
    );
    let w = warnings(&p);
    assert_eq!(w.len(), 31, "{w:?}");
    assert_eq!(
        w[0],
        "161:5: block \"Program Logic\" network 1: call of fcStepChooser is not read"
    );
    assert_eq!(
        w[30],
        "2302:5: 'block \"Program Logic\" network 22: comparator 'Eq' of 'Program Logic.#CurrentStep', a name with a space, which a comparison contact cannot name': a call, timer, counter, edge or function, not boolean logic: the coils it feeds are not derivable"
    );

    // V16 safety FBD (F_FBD): a muting FC read whole, the negated AND
    // output as its De Morgan form.
    let p = program("block-diagram-z3-Demo.xml");
    let scanners = "(Demo.#left_clear + (Demo.#is_slow * Demo.#mute_req)) * (Demo.#right_clear + Demo.#mute_req)";
    pinned(
        &p,
        &[
            ("Demo.#mute_granted", "Demo.#is_slow * Demo.#mute_req"),
            ("Demo.#scanners_ok", scanners),
            ("Demo.#stop", &format!("-({scanners}) + -Demo.#estop_clear")),
        ],
    );
    assert!(warnings(&p).is_empty(), "{:?}", warnings(&p));
    // A safety FB latching on edges (NBox resets, PBox sets) and a coil
    // chained after a coil: the edges are pulses, so nothing they reach is
    // derivable.
    let p = program("block-diagram-z3-Step2.xml");
    pinned(
        &p,
        &[
            ("Step2.#faults_clear", "! line 130"),
            ("DataFromSafety.running", "! line 130"),
            ("interlock", "! line 130"),
        ],
    );
    assert_eq!(
        warnings(&p),
        [
            "128:5: 'block \"Step2\" network 1: edge 'NBox' on 'Step2.#last_estop_clear' (a pulse, not a function of the signals)': a call, timer, counter, edge or function, not boolean logic: the coils it feeds are not derivable",
            "130:5: 'block \"Step2\" network 1: edge 'PBox' on 'Step2.#last_reset' (a pulse, not a function of the signals)': a call, timer, counter, edge or function, not boolean logic: the coils it feeds are not derivable",
        ]
    );
}
