use super::*;
use crate::sources::opcua::Names;

#[test]
fn monitored_nodes_group_bits_of_one_word_in_first_seen_order() {
    use cellwatch_models::signal::Signal;
    let node = |s: &str| TagNode::parse(&format!("ns=2;s={s}"), None).ok();
    let tag_nodes = Arc::new(vec![
        node("W1"),
        node("X"),
        node("W1"),
        node("Y"),
        node("W1"),
    ]);
    // Y is a number: its item says so.
    let mut tags: Vec<TagConfig> = (0..5)
        .map(|i| TagConfig::boolean(&format!("t{i}"), "ns=2;s=T", Signal::new("X0.00")))
        .collect();
    tags[3].value_type = ValueType::Float;
    let uses = Uses::of_tags(&tags);
    let id = |s: &str| NodeId::new(2, s);
    let pairs = tag_nodes
        .iter()
        .enumerate()
        .filter_map(|(t, n)| Some((n.as_ref()?.resolve(&[])?, t)));
    let m = Monitored::group(pairs, &uses, tag_nodes.clone(), Vec::new());
    assert_eq!(m.len(), 3);
    assert_eq!(m.node(0), Some((id("W1"), &[0, 2, 4][..])));
    assert_eq!(m.node(1), Some((id("X"), &[1][..])));
    assert_eq!(m.node(2), Some((id("Y"), &[3][..])));
    assert_eq!(m.node(3), None);
    assert_eq!(m.tags(0), Some(&[0, 2, 4][..]));
    assert_eq!(m.items[0].one(), None);
    assert_eq!(m.items[1].one(), Some(uses.of[1]));
    assert_eq!(
        uses.kind(m.items[2].one().unwrap()).value_type,
        ValueType::Float
    );
    assert_eq!(
        uses.kind(m.items[1].one().unwrap()).value_type,
        ValueType::Boolean
    );
    let tail: Vec<_> = m.nodes(1..10).map(|(i, n, _)| (i, n)).collect();
    assert_eq!(tail, [(1, id("X")), (2, id("Y"))]);
    assert_eq!(Monitored::group([], &uses, tag_nodes, Vec::new()).len(), 0);
}

#[test]
fn names_are_found_by_tag() {
    use cellwatch_models::signal::Signal;
    let tags: Vec<TagConfig> = ["ls_0", "", "Förderband 3"]
        .iter()
        .map(|n| TagConfig::boolean(n, "ns=2;s=T", Signal::new("X0.00")))
        .collect();
    let names = Names::of(&tags);
    assert_eq!(
        (&names[0], &names[1], &names[2]),
        ("ls_0", "", "Förderband 3")
    );
}

#[test]
fn uses_keep_each_distinct_way_of_reading_once() {
    use cellwatch_models::signal::Signal;
    let mut tags: Vec<TagConfig> = (0..5)
        .map(|i| {
            TagConfig::boolean(
                &format!("t{i}"),
                "ns=2;s=T",
                Signal::new(&format!("X0.0{i}")),
            )
        })
        .collect();
    tags[1].value_type = ValueType::Float;
    tags[1].deadband = Some(Deadband::Absolute(0.5));
    tags[3].value_type = ValueType::Float;
    tags[3].deadband = Some(Deadband::Percent(0.5));
    tags[4].sampling_interval = Some(Duration::from_millis(20));
    let uses = Uses::of_tags(&tags);
    assert_eq!(uses.kinds.len(), 4);
    for (i, t) in tags.iter().enumerate() {
        let u = &uses[i];
        assert_eq!(
            (u.value_type, u.bit, u.sampling, u.deadband),
            (t.value_type, t.bit, t.sampling_interval, t.deadband),
            "tag {i}"
        );
    }
}
