//! The event filters a SCADA client sends the alarm server: the fields of
//! the conditions' events it may name (in select clauses and in where
//! clauses' operands), registered in the server's type tree at start, and
//! the tests of every where-clause operator over a condition's event as
//! the server sends it. The filters are validated and evaluated by the
//! patched async-opcua-nodes (`vendor/README.md`); the event's fields are
//! `events.rs`'s.

use opcua::nodes::DefaultTypeTree;
use opcua::types::{NodeClass, NodeId, ObjectTypeId, QualifiedName};

/// Lets clients select the conditions' fields. async-opcua 0.19 checks a
/// select clause against the type tree, which knows only the properties a
/// type declares (so `AlarmConditionType`'s `Message` is refused) and no
/// empty path (so `ConditionId` is refused). Every field served is
/// registered under each condition type, and the empty path under
/// `ConditionType`. (A clause still refused is null in its place: the
/// patched async-opcua-nodes, `vendor/README.md`.)
pub(super) fn accept_condition_fields(tree: &mut DefaultTypeTree, ns: u16, ty: &NodeId) {
    tree.add_type_property(
        &NodeId::new(ns, "ConditionType.ConditionId"),
        &ObjectTypeId::ConditionType.into(),
        &[],
        NodeClass::Object,
    );
    let types: [NodeId; 4] = [
        ObjectTypeId::ConditionType.into(),
        ObjectTypeId::AcknowledgeableConditionType.into(),
        ObjectTypeId::AlarmConditionType.into(),
        ty.clone(),
    ];
    let mut paths: Vec<Vec<QualifiedName>> = [
        "EventId",
        "EventType",
        "SourceNode",
        "SourceName",
        "Time",
        "ReceiveTime",
        "Message",
        "Severity",
        "ConditionClassId",
        "ConditionClassName",
        "ConditionName",
        "BranchId",
        "Retain",
        "ClientUserId",
        "Comment",
        "Comment/SourceTimestamp",
        "LastSeverity",
        "LastSeverity/SourceTimestamp",
        "Quality",
        "Quality/SourceTimestamp",
        "SuppressedOrShelved",
        "ShelvingState/CurrentState",
        "ShelvingState/CurrentState/Id",
        "ShelvingState/UnshelveTime",
    ]
    .iter()
    .map(|p| p.split('/').map(|n| QualifiedName::new(0, n)).collect())
    .collect();
    for state in [
        "EnabledState",
        "ActiveState",
        "AckedState",
        "ConfirmedState",
    ] {
        for sub in ["", "/Id", "/TransitionTime", "/TrueState", "/FalseState"] {
            paths.push(
                format!("{state}{sub}")
                    .split('/')
                    .map(|n| QualifiedName::new(0, n))
                    .collect(),
            );
        }
    }
    let own = ["Culprits", "Consequence"]
        .into_iter()
        .chain(super::guidance::PROPERTIES.iter().map(|(name, _)| *name));
    for name in own {
        paths.push(vec![QualifiedName::new(ns, name)]);
    }
    for (t, ty) in types.iter().enumerate() {
        for (p, path) in paths.iter().enumerate() {
            let path: Vec<&QualifiedName> = path.iter().collect();
            tree.add_type_property(
                &NodeId::new(ns, format!("field.{t}.{p}")),
                ty,
                &path,
                NodeClass::Variable,
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use opcua::nodes::{BaseEventType, Event, ParsedEventFilter};
    use opcua::server::address_space::{AddressSpace, CoreNamespace};
    use opcua::types::{
        AttributeId, ByteString, ContentFilter, ContentFilterElement, DataTypeId, DateTime,
        EventFilter, EventFilterResult, ExpandedNodeId, FilterOperator, LocalizedText,
        NumericRange, ObjectId, Operand, SimpleAttributeOperand, StatusCode, Variant,
    };

    use super::*;
    use crate::services::alarm_server::conditions::{condition_event, Condition};
    use crate::services::alarm_server::events::CellAlarmEvent;

    const NAMESPACE: &str = "urn:cellwatch:alarms:m01";

    /// The server's type tree: namespace 0's types, `CellAlarmType` in the
    /// cell's namespace, the fields registered as at start; and that
    /// namespace's index. Made once: namespace 0 takes a while to load.
    fn type_tree() -> &'static (DefaultTypeTree, u16) {
        static TREE: std::sync::LazyLock<(DefaultTypeTree, u16)> = std::sync::LazyLock::new(|| {
            let mut tree = DefaultTypeTree::new();
            let mut core = AddressSpace::new();
            core.import_node_set(&CoreNamespace, tree.namespaces_mut());
            core.load_into_type_tree(&mut tree);
            let ns = tree.namespaces_mut().add_namespace(NAMESPACE);
            let ty = NodeId::new(ns, "CellAlarmType");
            tree.add_type_node(
                &ty,
                &ObjectTypeId::AlarmConditionType.into(),
                NodeClass::ObjectType,
            );
            accept_condition_fields(&mut tree, ns, &ty);
            (tree, ns)
        });
        &TREE
    }

    /// ESE's event as the alarm server sends it: raised, not acknowledged,
    /// high (750), at 2026-03-02 10:00 UTC.
    fn ese(ns: u16) -> CellAlarmEvent {
        let at: DateTime = "2026-03-02T10:00:00Z".parse().unwrap();
        let c = Condition {
            node: NodeId::new(ns, "m01.ese"),
            message: "ESE: X0.06 opened while the spindle ran".into(),
            severity: 750,
            culprits: "X0.06 = 0 (expected 1)".into(),
            consequence: "follows from hydraulic: Y2.00 = 0 (1 without hydraulic's fault)".into(),
            active: true,
            acked: false,
            enabled: true,
            active_at: at,
            acked_at: at,
            enabled_at: at,
            acked_by: String::new(),
            comment: String::new(),
            suppressed_or_shelved: false,
            shelved: None,
            shelving_node: NodeId::new(ns, "m01.ese.ShelvingState"),
            event_id: ByteString::from(b"m01-1".to_vec()),
            time: at,
            guidance: super::super::guidance::Guidance {
                corrective_action: "Release the emergency stop".into(),
                response_time: 300_000.0,
                ..Default::default()
            },
            before_overdue: None,
        };
        condition_event(
            "m01",
            &NodeId::new(ns, "CellAlarmType"),
            &NodeId::new(ns, "m01"),
            "ese",
            &c,
        )
    }

    /// A field of the event by its browse path under `BaseEventType`, as
    /// Python asyncua and node-opcua name them (`ActiveState/Id`).
    fn field(path: &str) -> Operand {
        Operand::simple_attribute(
            ObjectTypeId::BaseEventType,
            path,
            AttributeId::Value,
            NumericRange::None,
        )
    }

    /// A field by its path under `AlarmConditionType`.
    fn alarm_field(path: &str) -> Operand {
        Operand::simple_attribute(
            ObjectTypeId::AlarmConditionType,
            path,
            AttributeId::Value,
            NumericRange::None,
        )
    }

    fn lit(v: impl Into<Variant>) -> Operand {
        Operand::literal(v.into())
    }

    fn element(op: FilterOperator, operands: Vec<Operand>) -> ContentFilterElement {
        ContentFilterElement::from((op, operands))
    }

    /// The filter's result and, if accepted, whether `event` passes its
    /// where clause (its one field, EventId, sent).
    fn filter(
        tree: &DefaultTypeTree,
        elements: Vec<ContentFilterElement>,
        event: &dyn Event,
    ) -> (EventFilterResult, Result<bool, StatusCode>) {
        let (result, parsed) = ParsedEventFilter::new(
            EventFilter {
                select_clauses: Some(vec![SimpleAttributeOperand::new_value(
                    ObjectTypeId::BaseEventType,
                    "EventId",
                )]),
                where_clause: ContentFilter {
                    elements: Some(elements),
                },
            },
            tree,
        );
        let passes = parsed.map(|f| f.evaluate(event, 1, tree).is_some());
        (result, passes)
    }

    /// Whether ESE's event passes a where clause of `elements`, which the
    /// server accepts whole.
    fn passes(elements: Vec<ContentFilterElement>) -> bool {
        let (tree, ns) = type_tree();
        let ns = *ns;
        let (result, passes) = filter(tree, elements, &ese(ns));
        let statuses: Vec<StatusCode> = result
            .where_clause_result
            .element_results
            .iter()
            .flatten()
            .map(|r| r.status_code)
            .collect();
        assert!(statuses.iter().all(|s| s.is_good()), "{result:?}");
        passes.unwrap()
    }

    /// One element comparing `lhs` with `rhs` by `op`.
    fn compares(op: FilterOperator, lhs: Operand, rhs: Operand) -> bool {
        passes(vec![element(op, vec![lhs, rhs])])
    }

    #[test]
    fn in_list_of_event_types_as_python_asyncua_subscribes() {
        // asyncua's subscribe_events(server, AlarmConditionType): EventType
        // InList AlarmConditionType and every subtype browsed, NodeIds.
        let ns = type_tree().1;
        let alarm_types = |own: Operand| {
            vec![element(
                FilterOperator::InList,
                vec![
                    field("EventType"),
                    lit(NodeId::from(ObjectTypeId::AlarmConditionType)),
                    lit(NodeId::from(ObjectTypeId::LimitAlarmType)),
                    own,
                    lit(NodeId::from(ObjectTypeId::DiscreteAlarmType)),
                ],
            )]
        };
        assert!(passes(alarm_types(lit(NodeId::new(ns, "CellAlarmType")))));
        // As an ExpandedNodeId, by index or by the namespace's URI.
        assert!(passes(alarm_types(lit(ExpandedNodeId::from(NodeId::new(
            ns,
            "CellAlarmType"
        ))))));
        let by_uri = ExpandedNodeId::new_with_namespace(NAMESPACE, "CellAlarmType");
        assert!(passes(alarm_types(lit(by_uri))));
        // Not in the list: another namespace's, or an unknown URI's.
        assert!(!passes(alarm_types(lit(NodeId::new(
            ns + 1,
            "CellAlarmType"
        )))));
        let elsewhere = ExpandedNodeId::new_with_namespace("urn:elsewhere", "CellAlarmType");
        assert!(!passes(alarm_types(lit(elsewhere))));
        // Numbers and texts in a list.
        assert!(passes(vec![element(
            FilterOperator::InList,
            vec![field("Severity"), lit(250u16), lit(750i32), lit(1000u16)],
        )]));
        assert!(passes(vec![element(
            FilterOperator::InList,
            vec![field("SourceName"), lit("m02"), lit("m01")],
        )]));
        assert!(!passes(vec![element(
            FilterOperator::InList,
            vec![field("Severity"), lit(250u16), lit(500u16)],
        )]));
    }

    #[test]
    fn of_type_takes_the_types_the_event_is_of() {
        let ns = type_tree().1;
        let of = |t: Operand| passes(vec![element(FilterOperator::OfType, vec![t])]);
        assert!(of(lit(NodeId::from(ObjectTypeId::AlarmConditionType))));
        assert!(of(lit(NodeId::from(ObjectTypeId::ConditionType))));
        assert!(of(lit(NodeId::from(ObjectTypeId::BaseEventType))));
        assert!(of(lit(NodeId::new(ns, "CellAlarmType"))));
        assert!(of(lit(ExpandedNodeId::new_with_namespace(
            NAMESPACE,
            "CellAlarmType"
        ))));
        assert!(!of(lit(NodeId::from(ObjectTypeId::LimitAlarmType))));
        assert!(!of(lit(NodeId::from(ObjectTypeId::SystemEventType))));
    }

    #[test]
    fn equals_converts_as_part_4_says() {
        let ns = type_tree().1;
        let eq = |l, r| compares(FilterOperator::Equals, l, r);
        // NodeIds, and a NodeId against an ExpandedNodeId.
        assert!(eq(
            field("EventType"),
            lit(NodeId::new(ns, "CellAlarmType"))
        ));
        assert!(eq(
            lit(ExpandedNodeId::new_with_namespace(
                NAMESPACE,
                "CellAlarmType"
            )),
            field("EventType")
        ));
        assert!(!eq(
            field("EventType"),
            lit(NodeId::from(ObjectTypeId::AlarmConditionType))
        ));
        assert!(eq(
            alarm_field("ShelvingState/CurrentState/Id"),
            lit(NodeId::from(ObjectId::ShelvedStateMachineType_Unshelved))
        ));
        // Numbers of other types (Severity is a UInt16).
        assert!(eq(field("Severity"), lit(750i32)));
        assert!(eq(lit(750.0f64), field("Severity")));
        assert!(eq(field("Severity"), lit("750")));
        assert!(!eq(field("Severity"), lit(751u32)));
        // Strings and localized texts; a text against a string by its text.
        assert!(eq(field("SourceName"), lit("m01")));
        assert!(eq(alarm_field("ConditionName"), lit("ese")));
        assert!(!eq(field("SourceName"), lit("M01")));
        let message = "ESE: X0.06 opened while the spindle ran";
        assert!(eq(field("Message"), lit(message)));
        assert!(eq(field("Message"), lit(LocalizedText::from(message))));
        assert!(eq(field("Message"), lit(LocalizedText::new("en", message))));
        assert!(!eq(field("Message"), lit(LocalizedText::from("ESE"))));
        // Booleans, the states' ids.
        assert!(eq(alarm_field("ActiveState/Id"), lit(true)));
        assert!(eq(alarm_field("AckedState/Id"), lit(false)));
        assert!(eq(alarm_field("AckedState/Id"), lit(0u8)));
        // The cell's own field, in its namespace.
        let culprits = Operand::SimpleAttributeOperand(SimpleAttributeOperand {
            type_definition_id: NodeId::new(ns, "CellAlarmType"),
            browse_path: Some(vec![QualifiedName::new(ns, "Culprits")]),
            attribute_id: AttributeId::Value as u32,
            index_range: NumericRange::None,
        });
        assert!(eq(culprits, lit("X0.06 = 0 (expected 1)")));
        let consequence = Operand::SimpleAttributeOperand(SimpleAttributeOperand {
            type_definition_id: NodeId::new(ns, "CellAlarmType"),
            browse_path: Some(vec![QualifiedName::new(ns, "Consequence")]),
            attribute_id: AttributeId::Value as u32,
            index_range: NumericRange::None,
        });
        assert!(eq(
            consequence,
            lit("follows from hydraulic: Y2.00 = 0 (1 without hydraulic's fault)")
        ));
        // The master alarm database's guidance: a SCADA may filter on it
        // (the critical alarms that are overdue, say).
        let own = |name: &str| {
            Operand::SimpleAttributeOperand(SimpleAttributeOperand {
                type_definition_id: NodeId::new(ns, "CellAlarmType"),
                browse_path: Some(vec![QualifiedName::new(ns, name)]),
                attribute_id: AttributeId::Value as u32,
                index_range: NumericRange::None,
            })
        };
        assert!(eq(
            own("CorrectiveAction"),
            lit("Release the emergency stop")
        ));
        assert!(eq(own("ResponseTime"), lit(300_000.0f64)));
        assert!(eq(own("Overdue"), lit(false)));
        // A value of no type comparable: false, not an error.
        assert!(!eq(field("Time"), lit(NodeId::new(ns, "CellAlarmType"))));
    }

    #[test]
    fn comparisons_order_numbers_texts_and_times() {
        let before: DateTime = "2026-03-02T09:59:59Z".parse().unwrap();
        let cases = [
            (FilterOperator::GreaterThan, lit(500u16), true),
            (FilterOperator::GreaterThan, lit(750i64), false),
            (FilterOperator::GreaterThanOrEqual, lit(750.0f32), true),
            (FilterOperator::LessThan, lit(1000i32), true),
            (FilterOperator::LessThan, lit(750u16), false),
            (FilterOperator::LessThanOrEqual, lit(750u16), true),
            (FilterOperator::LessThanOrEqual, lit(749i16), false),
        ];
        for (op, rhs, expected) in cases {
            let shown = format!("Severity {op:?} {rhs:?}");
            assert_eq!(compares(op, field("Severity"), rhs), expected, "{shown}");
        }
        assert!(compares(
            FilterOperator::GreaterThan,
            field("Time"),
            lit(before)
        ));
        assert!(!compares(
            FilterOperator::LessThan,
            field("Time"),
            lit(before)
        ));
        assert!(compares(
            FilterOperator::LessThan,
            field("SourceName"),
            lit("m02")
        ));
    }

    #[test]
    fn like_matches_texts_and_strings() {
        let like = |l, pattern: &str| compares(FilterOperator::Like, l, lit(pattern));
        assert!(like(field("Message"), "%X0.06%"));
        assert!(like(field("Message"), "ESE: X0.0[0-9] %"));
        assert!(!like(field("Message"), "%X0.07%"));
        assert!(like(field("SourceName"), "m0_"));
        assert!(!like(field("SourceName"), "m0__"));
        // The regex's own characters are the text's.
        assert!(!like(field("SourceName"), "m01|x"));
        assert!(!like(field("SourceName"), "m0{2}1"));
        assert!(like(alarm_field("ConditionName"), "e%"));
        assert!(!like(field("Severity"), "%"));
    }

    #[test]
    fn between_is_inclusive() {
        let between = |lo: u16, hi: u16| {
            passes(vec![element(
                FilterOperator::Between,
                vec![field("Severity"), lit(lo), lit(hi)],
            )])
        };
        assert!(between(700, 800));
        assert!(between(750, 750));
        assert!(!between(1, 500));
        assert!(!between(751, 1000));
    }

    #[test]
    fn and_or_not_over_elements_with_three_values() {
        let active = element(
            FilterOperator::Equals,
            vec![alarm_field("ActiveState/Id"), lit(true)],
        );
        let acked = element(
            FilterOperator::Equals,
            vec![alarm_field("AckedState/Id"), lit(true)],
        );
        let two = |op| {
            passes(vec![
                element(op, vec![Operand::element(1), Operand::element(2)]),
                active.clone(),
                acked.clone(),
            ])
        };
        assert!(!two(FilterOperator::And));
        assert!(two(FilterOperator::Or));
        assert!(passes(vec![
            element(FilterOperator::Not, vec![Operand::element(1)]),
            acked.clone(),
        ]));
        assert!(!passes(vec![
            element(FilterOperator::Not, vec![Operand::element(1)]),
            active.clone(),
        ]));
        // A field the event lacks is NULL: FALSE And NULL is FALSE, TRUE
        // Or NULL is TRUE (Part 4 Table 120), Not NULL is NULL.
        let null = field("NoSuchField");
        let with_null = |op, known: ContentFilterElement| {
            passes(vec![
                element(FilterOperator::Not, vec![Operand::element(1)]),
                element(op, vec![Operand::element(2), null.clone()]),
                known,
            ])
        };
        assert!(with_null(FilterOperator::And, acked.clone()));
        assert!(!with_null(FilterOperator::Or, active.clone()));
        assert!(!passes(vec![element(
            FilterOperator::Not,
            vec![null.clone()]
        )]));
        assert!(!passes(vec![element(
            FilterOperator::Or,
            vec![lit(false), null]
        )]));
    }

    #[test]
    fn bitwise_and_or_and_cast() {
        // 750 = 0b10_1110_1110.
        let bits = |op, mask: u16, expected: u16| {
            passes(vec![
                element(
                    FilterOperator::Equals,
                    vec![Operand::element(1), lit(expected)],
                ),
                element(op, vec![field("Severity"), lit(mask)]),
            ])
        };
        assert!(bits(FilterOperator::BitwiseAnd, 512, 512));
        assert!(bits(FilterOperator::BitwiseAnd, 0x0F, 0x0E));
        assert!(bits(FilterOperator::BitwiseOr, 1, 751));
        assert!(!bits(FilterOperator::BitwiseOr, 1, 750));
        let cast = |to: DataTypeId, expected: Variant| {
            passes(vec![
                element(
                    FilterOperator::Equals,
                    vec![Operand::element(1), lit(expected)],
                ),
                element(
                    FilterOperator::Cast,
                    vec![field("Severity"), lit(NodeId::from(to))],
                ),
            ])
        };
        assert!(cast(DataTypeId::String, "750".into()));
        assert!(cast(DataTypeId::Double, 750.0f64.into()));
        assert!(!cast(DataTypeId::String, "75".into()));
    }

    #[test]
    fn is_null_takes_null_values_of_any_type() {
        let null = |o| passes(vec![element(FilterOperator::IsNull, vec![o])]);
        // The main branch's BranchId is the null NodeId; no comment yet.
        assert!(null(alarm_field("BranchId")));
        assert!(null(alarm_field("Comment")));
        assert!(null(field("NoSuchField")));
        assert!(!null(field("Severity")));
        assert!(!null(field("EventType")));
        assert!(!null(field("Message")));
    }

    #[test]
    fn operators_not_taken_are_refused_in_the_filter_result() {
        let (tree, ns) = type_tree();
        let ns = *ns;
        let cases = [
            (
                element(
                    FilterOperator::RelatedTo,
                    vec![
                        lit(NodeId::from(ObjectTypeId::AlarmConditionType)),
                        lit(NodeId::from(ObjectTypeId::BaseObjectType)),
                        lit(NodeId::from(opcua::types::ReferenceTypeId::HasComponent)),
                        lit(1u32),
                        lit(true),
                        lit(true),
                    ],
                ),
                StatusCode::BadFilterOperatorUnsupported,
            ),
            (
                element(
                    FilterOperator::InView,
                    vec![lit(NodeId::from(ObjectId::ViewsFolder))],
                ),
                StatusCode::BadFilterOperatorUnsupported,
            ),
            (
                element(
                    FilterOperator::Equals,
                    vec![
                        Operand::AttributeOperand(opcua::types::AttributeOperand {
                            node_id: NodeId::new(ns, "m01.ese"),
                            ..Default::default()
                        }),
                        lit(1u16),
                    ],
                ),
                StatusCode::BadFilterOperandInvalid,
            ),
        ];
        for (refused, status) in cases {
            let (result, parsed) = filter(
                tree,
                vec![
                    element(
                        FilterOperator::Or,
                        vec![Operand::element(1), Operand::element(2)],
                    ),
                    element(
                        FilterOperator::OfType,
                        vec![lit(NodeId::from(ObjectTypeId::AlarmConditionType))],
                    ),
                    refused,
                ],
                &ese(ns),
            );
            let statuses: Vec<StatusCode> = result
                .where_clause_result
                .element_results
                .iter()
                .flatten()
                .map(|r| r.status_code)
                .collect();
            assert_eq!(
                statuses,
                [StatusCode::Good, StatusCode::Good, status],
                "{result:?}"
            );
            assert_eq!(parsed, Err(StatusCode::BadEventFilterInvalid));
        }
    }

    #[test]
    fn a_refreshs_markers_pass_whatever_the_where_clause() {
        let (tree, ns) = type_tree();
        let ns = *ns;
        let alarms_only = vec![element(
            FilterOperator::InList,
            vec![
                field("EventType"),
                lit(NodeId::from(ObjectTypeId::AlarmConditionType)),
                lit(NodeId::new(ns, "CellAlarmType")),
            ],
        )];
        for marker in [
            ObjectTypeId::RefreshStartEventType,
            ObjectTypeId::RefreshEndEventType,
        ] {
            let e = BaseEventType::new_now(marker, ByteString::from(b"r".to_vec()), "refresh");
            let (_, passes) = filter(tree, alarms_only.clone(), &e);
            assert_eq!(passes, Ok(true), "{marker:?}");
        }
        let other = BaseEventType::new_now(
            ObjectTypeId::SystemEventType,
            ByteString::from(b"s".to_vec()),
            "system",
        );
        assert_eq!(filter(tree, alarms_only, &other).1, Ok(false));
    }
}
