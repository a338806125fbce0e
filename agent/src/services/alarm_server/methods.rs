//! Namespace 0's node manager with the condition methods a SCADA client
//! calls: `Acknowledge` (i=9111), `ConditionRefresh` (i=3875), `Disable`
//! (i=9028) and `Enable` (i=9027) — out of service and back, in ISA-18.2's
//! words — and the shelving state machine's `TimedShelve` (i=2949),
//! `OneShotShelve` (i=2948) and `Unshelve` (i=2947). They belong to namespace 0, so calls
//! to them reach the core node manager, which answers none: it is wrapped,
//! those taken here, everything else passed on. An acknowledgement or a
//! shelf goes to the cell loop ([`SessionCommand`]) and is answered Good
//! only once the loop took it.

use std::sync::Arc;

use async_trait::async_trait;
use opcua::nodes::BaseEventType;
use opcua::server::address_space::AddressSpace;
use opcua::server::diagnostics::NamespaceMetadata;
use opcua::server::node_manager::memory::{
    CoreNodeManagerBuilder, CoreNodeManagerImpl, InMemoryNodeManagerImpl,
    InMemoryNodeManagerImplBuilder,
};
use opcua::server::node_manager::{
    MethodCall, MonitoredItemRef, MonitoredItemUpdateRef, ParsedReadValueId, RequestContext,
    ServerContext,
};
use opcua::server::CreateMonitoredItem;
use opcua::sync::RwLock;
use opcua::types::{
    AttributeId, DataValue, MethodId, MonitoringMode, NodeId, ObjectId, ObjectTypeId, StatusCode,
    TimestampsToReturn, Variant,
};
use tokio::sync::{mpsc, oneshot};

use super::conditions::Conditions;
use super::users::Users;
use crate::operator::Action;
use crate::step::{SessionCommand, SessionOutcome};

/// How much of an acknowledgement's comment is journaled (bytes).
const COMMENT_BYTES: usize = 256;

/// What a method asks of the cell loop: the action on an alarm, a shelf's
/// length, the operator's comment (may be empty).
struct Asked {
    action: Action,
    alarm: String,
    value: Option<String>,
    comment: String,
}

/// Builds the core node manager wrapped ([`AlarmCore`]).
pub(super) struct AlarmCoreBuilder {
    pub(super) conditions: Arc<Conditions>,
    pub(super) users: Users,
    pub(super) acks: mpsc::Sender<SessionCommand>,
}

impl InMemoryNodeManagerImplBuilder for AlarmCoreBuilder {
    type Impl = AlarmCore;

    fn build(self, context: ServerContext, address_space: &mut AddressSpace) -> AlarmCore {
        AlarmCore {
            core: CoreNodeManagerBuilder.build(context, address_space),
            conditions: self.conditions,
            users: self.users,
            acks: self.acks,
        }
    }
}

/// The core node manager, with `Acknowledge` and `ConditionRefresh`.
pub(super) struct AlarmCore {
    core: CoreNodeManagerImpl,
    conditions: Arc<Conditions>,
    users: Users,
    /// To the cell loop: each acknowledgement a session asks for.
    acks: mpsc::Sender<SessionCommand>,
}

impl AlarmCore {
    /// The session's user and the operator they act as; refused for an
    /// anonymous session or a user acting as nobody.
    fn operator_of(&self, context: &RequestContext, alarm: &str) -> Option<(String, String)> {
        let token = context.user_token();
        if token.is_anonymous() {
            return None;
        }
        let user = token.0.clone();
        let Some(operator) = self.users.operator(&user) else {
            tracing::warn!(user = %crate::operator::escaped(&user), alarm, "a command over OPC UA refused: the user acts as no operator");
            return None;
        };
        Some((user, operator))
    }

    /// Hands `asked` to the cell loop and waits until it is done and
    /// journaled: what it came to.
    async fn ask_loop(
        &self,
        asked: SessionCommand,
        reply: oneshot::Receiver<SessionOutcome>,
    ) -> Option<SessionOutcome> {
        self.acks.send(asked).await.ok()?;
        reply.await.ok()
    }

    /// `Acknowledge(EventId, Comment)` on a condition, by the session's
    /// user as the operator they act as, through the cell loop.
    async fn acknowledge(&self, context: &RequestContext, call: &mut MethodCall) {
        if context.user_token().is_anonymous() {
            call.set_status(StatusCode::BadUserAccessDenied);
            return;
        }
        let args = call.arguments();
        let event_id = match args.first() {
            Some(Variant::ByteString(b)) => b.clone(),
            _ => {
                call.set_status(StatusCode::BadInvalidArgument);
                return;
            }
        };
        let Some((alarm, condition)) = self.conditions.by_node(call.object_id()) else {
            call.set_status(StatusCode::BadNodeIdUnknown);
            return;
        };
        if !condition.names(&event_id) {
            call.set_status(StatusCode::BadEventIdUnknown);
            return;
        }
        if condition.acked {
            call.set_status(StatusCode::BadConditionBranchAlreadyAcked);
            return;
        }
        let comment = match args.get(1) {
            Some(Variant::LocalizedText(t)) => t.text.as_ref(),
            _ => "",
        };
        let comment = crate::operator::clip(&crate::operator::escaped(comment), COMMENT_BYTES);
        let asked = Asked {
            action: Action::Ack,
            alarm,
            value: None,
            comment,
        };
        self.carry_out(
            context,
            call,
            asked,
            StatusCode::BadConditionBranchAlreadyAcked,
        )
        .await;
    }

    /// `TimedShelve(ShelvingTime)`, `OneShotShelve()` or `Unshelve()` on
    /// a condition's `ShelvingState`, by the session's user as the
    /// operator they act as (who needs `shelve` or `unshelve`), through
    /// the cell loop.
    async fn shelving(&self, context: &RequestContext, call: &mut MethodCall, method: MethodId) {
        if context.user_token().is_anonymous() {
            call.set_status(StatusCode::BadUserAccessDenied);
            return;
        }
        let Some((alarm, condition)) = self.conditions.by_shelving_node(call.object_id()) else {
            call.set_status(StatusCode::BadNodeIdUnknown);
            return;
        };
        let (action, value) = match method {
            MethodId::ShelvedStateMachineType_TimedShelve => {
                let ms = match call.arguments().first() {
                    Some(Variant::Double(ms)) if ms.is_finite() && *ms >= 1.0 => *ms,
                    _ => {
                        call.set_status(StatusCode::BadInvalidArgument);
                        return;
                    }
                };
                (Action::Shelve, Some(format!("{}ms", ms.round() as u64)))
            }
            MethodId::ShelvedStateMachineType_OneShotShelve => {
                (Action::Shelve, Some("once".to_string()))
            }
            _ => (Action::Unshelve, None),
        };
        match (action, condition.shelved) {
            (Action::Shelve, Some(_)) => {
                call.set_status(StatusCode::BadConditionAlreadyShelved);
                return;
            }
            (Action::Unshelve, None) => {
                call.set_status(StatusCode::BadConditionNotShelved);
                return;
            }
            _ => {}
        }
        let asked = Asked {
            action,
            alarm,
            value,
            comment: String::new(),
        };
        self.carry_out(context, call, asked, StatusCode::BadConditionNotShelved)
            .await;
    }

    /// `Disable()` or `Enable()` on a condition: its alarm taken out of
    /// service or put back (ISA-18.2), by the session's user as the
    /// operator they act as (who needs `out-of-service` or `in-service`),
    /// through the cell loop.
    async fn enabling(&self, context: &RequestContext, call: &mut MethodCall, enable: bool) {
        if context.user_token().is_anonymous() {
            call.set_status(StatusCode::BadUserAccessDenied);
            return;
        }
        let Some((alarm, condition)) = self.conditions.by_node(call.object_id()) else {
            call.set_status(StatusCode::BadNodeIdUnknown);
            return;
        };
        let already = if enable {
            StatusCode::BadConditionAlreadyEnabled
        } else {
            StatusCode::BadConditionAlreadyDisabled
        };
        if condition.enabled == enable {
            call.set_status(already);
            return;
        }
        let action = if enable {
            Action::InService
        } else {
            Action::OutOfService
        };
        let asked = Asked {
            action,
            alarm,
            value: None,
            comment: String::new(),
        };
        self.carry_out(context, call, asked, already).await;
    }

    /// `asked`, by the session's user as the operator they act as, carried
    /// out by the cell loop and journaled: the call's status, `wrong_state`
    /// when the alarm is not in a state the method applies to.
    async fn carry_out(
        &self,
        context: &RequestContext,
        call: &mut MethodCall,
        asked: Asked,
        wrong_state: StatusCode,
    ) {
        let Some((user, operator)) = self.operator_of(context, &asked.alarm) else {
            call.set_status(StatusCode::BadUserAccessDenied);
            return;
        };
        let (reply, outcome) = oneshot::channel();
        let command = SessionCommand {
            user,
            operator,
            action: asked.action,
            alarm: asked.alarm,
            value: asked.value,
            comment: asked.comment,
            reply,
        };
        let status = match self.ask_loop(command, outcome).await {
            Some(SessionOutcome::Accepted(_)) => {
                call.set_outputs(Vec::new());
                StatusCode::Good
            }
            Some(SessionOutcome::Denied(_)) => StatusCode::BadUserAccessDenied,
            Some(SessionOutcome::WrongState(_)) => wrong_state,
            // Only a shelf has a length.
            Some(SessionOutcome::OutOfRange(_)) => StatusCode::BadShelvingTimeOutOfRange,
            Some(SessionOutcome::Refused(_)) => StatusCode::BadInvalidState,
            None => StatusCode::BadShutdown,
        };
        call.set_status(status);
    }

    /// `ConditionRefresh(SubscriptionId)`: a refresh start, every retained
    /// condition's event and a refresh end, to that subscription's event
    /// items on the `Server` object or the cell.
    fn condition_refresh(&self, context: &RequestContext, call: &mut MethodCall) {
        let Some(Variant::UInt32(subscription)) = call.arguments().first().cloned() else {
            call.set_status(StatusCode::BadInvalidArgument);
            return;
        };
        let Some(served) = self.conditions.served.get() else {
            call.set_status(StatusCode::BadInvalidState);
            return;
        };
        let server: NodeId = ObjectId::Server.into();
        let marker = |kind: ObjectTypeId, text: &str| {
            let mut e = BaseEventType::new_now(kind, self.conditions.next_event_id(), text);
            e.source_node = server.clone();
            e.source_name = "Server".into();
            e.severity = 1;
            e
        };
        let start = marker(
            ObjectTypeId::RefreshStartEventType,
            "ConditionRefresh start",
        );
        let end = marker(ObjectTypeId::RefreshEndEventType, "ConditionRefresh end");
        let retained = self.conditions.retained();
        let Some(subscriptions) = context
            .subscriptions
            .get_session_subscriptions(context.session_id)
        else {
            call.set_status(StatusCode::BadSubscriptionIdInvalid);
            return;
        };
        let type_tree = context.type_tree.read();
        let mut subscriptions = subscriptions.lock();
        let Some(sub) = subscriptions.get_mut(subscription) else {
            call.set_status(StatusCode::BadSubscriptionIdInvalid);
            return;
        };
        let items: Vec<u32> = sub
            .items()
            .filter(|i| {
                let r = i.item_to_monitor();
                r.attribute_id == AttributeId::EventNotifier
                    && (r.node_id == server || r.node_id == served.notifier)
            })
            .map(|i| i.id())
            .collect();
        for id in &items {
            sub.notify_event(id, &start, &*type_tree);
            for e in &retained {
                sub.notify_event(id, e, &*type_tree);
            }
            sub.notify_event(id, &end, &*type_tree);
        }
        call.set_outputs(Vec::new());
        call.set_status(StatusCode::Good);
    }
}

#[async_trait]
impl InMemoryNodeManagerImpl for AlarmCore {
    async fn init(&self, address_space: &mut AddressSpace, context: ServerContext) {
        self.core.init(address_space, context).await;
    }

    fn name(&self) -> &str {
        self.core.name()
    }

    fn namespaces(&self) -> Vec<NamespaceMetadata> {
        self.core.namespaces()
    }

    async fn read_values(
        &self,
        context: &RequestContext,
        address_space: &RwLock<AddressSpace>,
        nodes: &[&ParsedReadValueId],
        max_age: f64,
        timestamps_to_return: TimestampsToReturn,
    ) -> Vec<DataValue> {
        self.core
            .read_values(context, address_space, nodes, max_age, timestamps_to_return)
            .await
    }

    async fn create_value_monitored_items(
        &self,
        context: &RequestContext,
        address_space: &RwLock<AddressSpace>,
        items: &mut [&mut &mut CreateMonitoredItem],
    ) {
        self.core
            .create_value_monitored_items(context, address_space, items)
            .await;
    }

    async fn set_monitoring_mode(
        &self,
        context: &RequestContext,
        mode: MonitoringMode,
        items: &[&MonitoredItemRef],
    ) {
        self.core.set_monitoring_mode(context, mode, items).await;
    }

    async fn modify_monitored_items(
        &self,
        context: &RequestContext,
        items: &[&MonitoredItemUpdateRef],
    ) {
        self.core.modify_monitored_items(context, items).await;
    }

    async fn delete_monitored_items(&self, context: &RequestContext, items: &[&MonitoredItemRef]) {
        self.core.delete_monitored_items(context, items).await;
    }

    async fn call(
        &self,
        context: &RequestContext,
        address_space: &RwLock<AddressSpace>,
        methods_to_call: &mut [&mut &mut MethodCall],
    ) -> Result<(), StatusCode> {
        // The library checked each call first: the object has the method
        // as a component (in this address space), it is executable, and
        // not too many arguments came.
        let mut rest: Vec<&mut &mut MethodCall> = Vec::new();
        for m in methods_to_call.iter_mut() {
            match m.method_id().as_method_id() {
                Ok(MethodId::AcknowledgeableConditionType_Acknowledge) => {
                    self.acknowledge(context, m).await;
                }
                Ok(MethodId::ConditionType_ConditionRefresh) => {
                    self.condition_refresh(context, m);
                }
                Ok(MethodId::ConditionType_Enable) => self.enabling(context, m, true).await,
                Ok(MethodId::ConditionType_Disable) => self.enabling(context, m, false).await,
                Ok(
                    method @ (MethodId::ShelvedStateMachineType_TimedShelve
                    | MethodId::ShelvedStateMachineType_OneShotShelve
                    | MethodId::ShelvedStateMachineType_Unshelve),
                ) => {
                    self.shelving(context, m, method).await;
                }
                _ => rest.push(&mut **m),
            }
        }
        self.core.call(context, address_space, &mut rest).await
    }
}
