# A SCADA client of Python asyncua for the alarm server's interoperability
# test, subscribing as that library does by default:
# subscribe_events(Server, AlarmConditionType), whose where clause is
# "EventType InList [AlarmConditionType and every subtype browsed]".
# Basic256Sha256 + SignAndEncrypt, a user name and password; the server's
# certificate is the one in PKI/trusted/certs/cellwatch.der.
#
#   python scada.py URL PKI_DIR USER PASSWORD
#
# Prints "certificate <own certificate, DER>" at once (to be trusted by the
# server), then waits for "connect" on standard input; once subscribed,
# prints "connected". Each event: "event {json}" with eventId (hex),
# eventType, sourceName, message, severity, conditionName, active, acked,
# retain, clientUserId, comment and conditionId (node ids as asyncua writes
# them). Standard input then:
#   ack CONDITION_ID EVENT_ID COMMENT   Acknowledge (i=9111) on the condition,
#                       the event's id (hex), the comment the rest of the
#                       line: "ack <status name>"
#   refresh             ConditionRefresh on the subscription: "refresh
#                       <status name>"
#   quit
import asyncio
import json
import sys
from pathlib import Path

from asyncua import Client, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography.x509.oid import ExtendedKeyUsageOID

APPLICATION_URI = "urn:cellwatch:test:asyncua-scada"
FIELDS = {
    "eventId": "EventId",
    "eventType": "EventType",
    "sourceName": "SourceName",
    "message": "Message",
    "severity": "Severity",
    "conditionName": "ConditionName",
    "active": "ActiveState/Id",
    "acked": "AckedState/Id",
    "retain": "Retain",
    "clientUserId": "ClientUserId",
    "comment": "Comment",
    # asyncua's name for the ConditionId clause (ConditionType, no path).
    "conditionId": "NodeId",
}


def plain(v):
    if isinstance(v, bytes):
        return v.hex()
    if isinstance(v, ua.NodeId):
        return v.to_string()
    if isinstance(v, ua.LocalizedText):
        return v.Text
    return v


def status_name(code):
    return ua.status_codes.get_name_and_doc(code)[0]


class Events:
    def event_notification(self, event):
        e = {name: plain(getattr(event, field, None)) for name, field in FIELDS.items()}
        print("event " + json.dumps(e), flush=True)


async def main():
    url, pki, user, password = sys.argv[1:5]
    pki = Path(pki)
    pki.mkdir(parents=True, exist_ok=True)
    key, cert = pki / "scada.pem", pki / "scada.der"
    await setup_self_signed_certificate(
        key,
        cert,
        APPLICATION_URI,
        "localhost",
        [ExtendedKeyUsageOID.CLIENT_AUTH],
        {"commonName": "cellwatch interop SCADA (asyncua)"},
    )
    print(f"certificate {cert}", flush=True)
    loop = asyncio.get_running_loop()

    async def line():
        return (await loop.run_in_executor(None, sys.stdin.readline)).strip() or "quit"

    while (await line()) != "connect":
        pass

    client = Client(url)
    client.application_uri = APPLICATION_URI
    client.set_user(user)
    client.set_password(password)
    await client.set_security(
        SecurityPolicyBasic256Sha256,
        certificate=str(cert),
        private_key=str(key),
        server_certificate=str(pki / "trusted" / "certs" / "cellwatch.der"),
        mode=ua.MessageSecurityMode.SignAndEncrypt,
    )
    async with client:
        subscription = await client.create_subscription(50, Events())
        await subscription.subscribe_events(client.nodes.server, ua.ObjectIds.AlarmConditionType)
        print("connected", flush=True)
        while True:
            command, _, rest = (await line()).partition(" ")
            if command == "quit":
                break
            if command == "ack":
                condition, event_id, comment = (rest.split(" ", 2) + [""])[:3]
                try:
                    await client.get_node(condition).call_method(
                        ua.NodeId(ua.ObjectIds.AcknowledgeableConditionType_Acknowledge),
                        ua.Variant(bytes.fromhex(event_id), ua.VariantType.ByteString),
                        ua.Variant(ua.LocalizedText(comment), ua.VariantType.LocalizedText),
                    )
                    print("ack Good", flush=True)
                except ua.UaStatusCodeError as e:
                    print(f"ack {status_name(e.code)}", flush=True)
            elif command == "refresh":
                try:
                    await client.get_node(ua.ObjectIds.ConditionType).call_method(
                        ua.NodeId(ua.ObjectIds.ConditionType_ConditionRefresh),
                        ua.Variant(subscription.subscription_id, ua.VariantType.UInt32),
                    )
                    print("refresh Good", flush=True)
                except ua.UaStatusCodeError as e:
                    print(f"refresh {status_name(e.code)}", flush=True)


asyncio.run(main())
