// A SCADA client of node-opcua for the alarm server's interoperability test:
// Basic256Sha256 + SignAndEncrypt, a user name and password, the server's
// certificate trusted only from PKI/trusted/certs; subscribes to the events
// of the Server object (i=2253) with the fields a SCADA shows.
//
//   node scada.js URL PKI_DIR USER PASSWORD NAMESPACE_URI
//
// Prints "certificate <own certificate, DER>" at once (to be trusted by the
// server), then waits for "connect" on standard input; once subscribed,
// prints "connected". Each event: "event {json}" with eventId (hex),
// eventType, sourceName, message, severity, conditionName, active, acked,
// retain, clientUserId, comment, suppressedOrShelved, shelving (the
// ShelvingState's CurrentState/Id), conditionId and culprits (NAMESPACE_URI's
// CellAlarmType's Culprits). Standard input then:
//   ack CONDITION_ID EVENT_ID COMMENT   Acknowledge (i=9111) on the condition
//                       (a node id as printed), the event's id (hex), the
//                       comment the rest of the line: "ack <status name>"
//   call OBJECT METHOD [MS]  a method (node ids) with no argument, or a
//                       Duration of MS milliseconds: "call <status name>"
//   refresh             ConditionRefresh on the subscription: "refresh
//                       <status name>", the retained conditions' events
//                       between a RefreshStart and a RefreshEnd event
//   quit
"use strict";
const fs = require("fs");
const path = require("path");
const readline = require("readline");
const {
  OPCUAClient, MessageSecurityMode, SecurityPolicy, UserTokenType, AttributeIds,
  TimestampsToReturn, ClientSubscription, ClientMonitoredItem, constructEventFilter,
  SimpleAttributeOperand, coerceNodeId, NodeId, DataType, Variant,
} = require("node-opcua-client");
const { OPCUACertificateManager } = require("node-opcua-certificate-manager");
const { ownCertificate } = require("./certificate");

const APPLICATION_URI = "urn:cellwatch:test:node-opcua-scada";
const FIELDS = [
  "EventId", "EventType", "SourceName", "Message", "Severity", "ConditionName",
  "ActiveState.Id", "AckedState.Id", "Retain", "ClientUserId", "Comment", "SuppressedOrShelved",
  "ShelvingState.CurrentState.Id", "ConditionId",
];
const NAMES = [
  "eventId", "eventType", "sourceName", "message", "severity", "conditionName",
  "active", "acked", "retain", "clientUserId", "comment", "suppressedOrShelved", "shelving",
  "conditionId", "culprits",
];

function plain(v) {
  if (v === null || v === undefined || v.value === null || v.value === undefined) {
    return null;
  }
  const x = v.value;
  if (Buffer.isBuffer(x)) {
    return x.toString("hex");
  }
  if (x instanceof NodeId) {
    return x.toString();
  }
  if (typeof x === "object" && "text" in x) {
    return x.text;
  }
  return x;
}

async function main() {
  const [url, pkiDir, user, password, uri] = process.argv.slice(2);
  const { certFile, keyFile } = await ownCertificate(pkiDir, APPLICATION_URI, "cellwatch interop SCADA");
  const der = Buffer.from(
    fs.readFileSync(certFile, "utf8").replace(/-----[^-]+-----/g, "").replace(/\s+/g, ""), "base64");
  const derFile = path.join(pkiDir, "scada.der");
  fs.writeFileSync(derFile, der);
  console.log(`certificate ${derFile}`);
  const lines = readline.createInterface({ input: process.stdin });
  const queue = [];
  let wake = null;
  lines.on("line", (l) => { queue.push(l); if (wake) { wake(); } });
  lines.on("close", () => { queue.push("quit"); if (wake) { wake(); } });
  const next = async () => {
    while (queue.length === 0) {
      await new Promise((r) => { wake = r; });
    }
    return queue.shift();
  };
  while ((await next()) !== "connect") { /* wait */ }

  const clientCertificateManager = new OPCUACertificateManager({
    rootFolder: pkiDir,
    automaticallyAcceptUnknownCertificate: false,
  });
  await clientCertificateManager.initialize();
  const client = OPCUAClient.create({
    applicationName: "cellwatch interop SCADA",
    applicationUri: APPLICATION_URI,
    clientCertificateManager,
    certificateFile: certFile,
    privateKeyFile: keyFile,
    securityMode: MessageSecurityMode.SignAndEncrypt,
    securityPolicy: SecurityPolicy.Basic256Sha256,
    endpointMustExist: false,
    connectionStrategy: { maxRetry: 0 },
  });
  await client.connect(url);
  const session = await client.createSession({ type: UserTokenType.UserName, userName: user, password });
  const namespaces = await session.readNamespaceArray();
  const ns = namespaces.indexOf(uri);
  if (ns < 0) {
    throw new Error(`the server has no namespace ${uri}: ${namespaces.join(", ")}`);
  }
  const filter = constructEventFilter(FIELDS);
  filter.selectClauses.push(new SimpleAttributeOperand({
    typeDefinitionId: coerceNodeId(`ns=${ns};s=CellAlarmType`),
    browsePath: [{ namespaceIndex: ns, name: "Culprits" }],
    attributeId: AttributeIds.Value,
  }));
  const subscription = ClientSubscription.create(session, {
    requestedPublishingInterval: 50, requestedLifetimeCount: 600, requestedMaxKeepAliveCount: 20,
    maxNotificationsPerPublish: 1000, publishingEnabled: true, priority: 0,
  });
  await new Promise((resolve) => subscription.on("started", resolve));
  const item = ClientMonitoredItem.create(subscription,
    { nodeId: "i=2253", attributeId: AttributeIds.EventNotifier },
    { samplingInterval: 0, queueSize: 100, discardOldest: true, filter },
    TimestampsToReturn.Both);
  item.on("changed", (fields) => {
    const e = {};
    fields.forEach((v, i) => { e[NAMES[i]] = plain(v); });
    console.log(`event ${JSON.stringify(e)}`);
  });
  await new Promise((resolve, reject) => {
    item.on("initialized", resolve);
    item.on("err", (m) => reject(new Error(`event item refused: ${m}`)));
  });
  console.log("connected");

  for (;;) {
    const line = await next();
    const [command, ...rest] = line.split(" ");
    if (command === "quit") {
      break;
    } else if (command === "ack") {
      const [conditionId, eventId, ...comment] = rest;
      const result = await session.call({
        objectId: coerceNodeId(conditionId),
        methodId: coerceNodeId("i=9111"),
        inputArguments: [
          new Variant({ dataType: DataType.ByteString, value: Buffer.from(eventId, "hex") }),
          new Variant({ dataType: DataType.LocalizedText, value: { text: comment.join(" ") } }),
        ],
      });
      console.log(`ack ${result.statusCode.name}`);
    } else if (command === "call") {
      const [objectId, methodId, ms] = rest;
      const inputArguments = ms === undefined ? [] : [new Variant({ dataType: DataType.Double, value: Number(ms) })];
      const result = await session.call({ objectId: coerceNodeId(objectId), methodId: coerceNodeId(methodId), inputArguments });
      console.log(`call ${result.statusCode.name}`);
    } else if (command === "refresh") {
      const result = await session.call({
        objectId: coerceNodeId("i=2782"),
        methodId: coerceNodeId("i=3875"),
        inputArguments: [new Variant({ dataType: DataType.UInt32, value: subscription.subscriptionId })],
      });
      console.log(`refresh ${result.statusCode.name}`);
    } else {
      console.log(`unknown command ${command}`);
    }
  }
  await subscription.terminate();
  await session.close();
  await client.disconnect();
  process.exit(0);
}

main().catch((e) => {
  console.error(e);
  process.exit(1);
});
