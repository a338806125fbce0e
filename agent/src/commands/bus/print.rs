//! An alarm event as `cellwatch alarms` and `cellwatch archive` print it:
//! one line (what is kept from operators first, then the event), its
//! culprits and the master alarm database's corrective action.

use std::io::Write;

use crate::payload::AlarmPayload;

/// Prints `a`, one line (and its culprits, its corrective action); `now`
/// (ms) for the current state, where an occurrence past its response time
/// is said `OVERDUE` (not for events of the past: a later one may have
/// acknowledged it).
pub(crate) fn print_alarm(
    out: &mut dyn Write,
    a: &AlarmPayload,
    json: bool,
    now: Option<u64>,
) -> std::io::Result<()> {
    if json {
        return writeln!(out, "{}", serde_json::to_string(a).unwrap_or_default());
    }
    let step = a
        .fault_step
        .map(|s| format!(" step {s}"))
        .unwrap_or_default();
    // Kept from operators: said first, so that no one takes it for an
    // alarm to act on.
    let mut kept = String::new();
    if let Some(s) = &a.shelved {
        let until = s.until.as_deref().unwrap_or("it clears");
        kept += &format!("SHELVED until {until} by {} ({})  ", s.by, s.reason);
    }
    if let Some(r) = &a.out_of_service {
        kept += &format!("OUT OF SERVICE since {} by {} ({})  ", r.at, r.by, r.reason);
    }
    if let Some(d) = &a.suppressed_by_design {
        kept += &format!(
            "SUPPRESSED BY DESIGN in mode {} since {}  ",
            d.mode, d.since
        );
    }
    // Unacknowledged past its response time: said first too, as a
    // reminder that someone must act now.
    if now.is_some_and(|now| a.overdue(now)) {
        let within = a.guidance.as_ref().and_then(|g| g.response_time.as_deref());
        kept += &format!("OVERDUE (response time {})  ", within.unwrap_or_default());
    }
    let mut consequence = String::new();
    if let Some(c) = &a.consequence {
        if c.suppressed {
            kept += "SUPPRESSED  ";
        }
        consequence = format!(" (consequence of {}", c.cause);
        if c.first_out != c.cause {
            consequence += &format!(", first-out {}", c.first_out);
        }
        if !c.through.is_empty() {
            consequence += &format!(", through {}", c.through_text());
        }
        consequence.push(')');
    }
    // Who acknowledged it, and what they said.
    if let Some(by) = &a.acked_by {
        consequence += &format!(" (by {by}");
        if let Some(c) = &a.ack_comment {
            consequence += &format!(": {c}");
        }
        consequence.push(')');
    }
    // Operators' and the journal's text on one line each: a newline in a
    // reason never prints a line of its own.
    let line = format!(
        "{}  {}/{}  {kept}{} {} [{}] {}{step}: {}{consequence}",
        a.at, a.cell, a.id, a.transition, a.state, a.severity, a.fault_type, a.message
    );
    writeln!(out, "{}", crate::operator::escaped(&line))?;
    for c in &a.culprits {
        writeln!(out, "    {}", crate::operator::escaped(&c.line()))?;
    }
    // The master alarm database's corrective action, where the cell has it.
    if let Some(g) = a
        .guidance
        .as_ref()
        .filter(|g| !g.corrective_action.is_empty())
    {
        let within = g
            .response_time
            .as_ref()
            .map_or_else(String::new, |t| format!(" (within {t})"));
        let line = format!("    do{within}: {}", g.corrective_action);
        writeln!(out, "{}", crate::operator::escaped(&line))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::print_alarm;
    use crate::payload::AlarmPayload;

    #[test]
    fn an_acknowledgement_prints_who_made_it_and_their_comment() {
        let a: AlarmPayload = serde_json::from_value(serde_json::json!({
            "schema": "cellwatch.alarm.v1", "cell": "m01ps0004", "id": "ese",
            "kind": "switching", "severity": "critical", "state": "active_acknowledged",
            "transition": "acknowledged", "at": "2026-11-28T10:00:00.000Z",
            "raised_at": "2026-11-28T09:59:00.000Z", "cleared_at": null,
            "acked_by": "kim", "ack_comment": "tool changed\nnext line",
            "fault_type": "ESE", "fault_step": 6, "culprits": [], "message": "ESE at step 6"
        }))
        .unwrap();
        let mut out = Vec::new();
        print_alarm(&mut out, &a, false, None).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert_eq!(text.lines().count(), 1, "{text}");
        assert!(
            text.ends_with("ESE step 6: ESE at step 6 (by kim: tool changed\\nnext line)\n"),
            "{text}"
        );
        // Cleared afterwards, acknowledged without a comment: who, still.
        let mut cleared = a.clone();
        cleared.transition = cellwatch_models::alarm::Transition::Cleared;
        cleared.ack_comment = None;
        let mut out = Vec::new();
        print_alarm(&mut out, &cleared, false, None).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert!(text.ends_with("ESE at step 6 (by kim)\n"), "{text}");
    }

    #[test]
    fn the_current_state_says_an_alarm_past_its_response_time_is_overdue() {
        let a: AlarmPayload = serde_json::from_value(serde_json::json!({
            "schema": "cellwatch.alarm.v1", "cell": "m01ps0004", "id": "ese",
            "kind": "switching", "severity": "critical", "state": "active_unacknowledged",
            "transition": "raised", "at": "2026-11-28T10:00:00.000Z",
            "raised_at": "2026-11-28T10:00:00.000Z", "cleared_at": null, "acked_by": null,
            "fault_type": "ESE", "fault_step": 6, "culprits": [], "message": "ESE at step 6",
            "guidance": {"class": "safety", "consequence_of_inaction": "",
                         "corrective_action": "Release the emergency stop",
                         "response_time": "5m"}
        }))
        .unwrap();
        let raised = crate::clock::parse_time("2026-11-28T10:00:00.000Z", 0).unwrap();
        let printed = |now: Option<u64>| {
            let mut out = Vec::new();
            print_alarm(&mut out, &a, false, now).unwrap();
            String::from_utf8(out).unwrap()
        };
        assert!(!printed(Some(raised + 299_999)).contains("OVERDUE"));
        let late = printed(Some(raised + 300_000));
        assert!(
            late.contains("  OVERDUE (response time 5m)  raised"),
            "{late}"
        );
        assert!(
            late.contains("    do (within 5m): Release the emergency stop"),
            "{late}"
        );
        // An event of the past is printed as it was.
        assert!(!printed(None).contains("OVERDUE"));
    }
}
