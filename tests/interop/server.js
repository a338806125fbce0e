// An independent OPC UA server (node-opcua) for cellwatch's interoperability
// tests: Basic256Sha256 + SignAndEncrypt only, client certificates trusted
// only from PKI/trusted/certs, N Boolean tags T0..T(N-1) in namespace URI.
//
//   node server.js PORT PKI_DIR N URI
//
// Prints "ready <own certificate, DER>" once listening, "expired
// subscription ID" when one outlives its lifetime. Standard input:
//   set NAME 0|1        write a tag
//   toggle NAME K       write it K times, alternating, as fast as possible
//   delete NAME         delete a tag's node; add NAME 0|1 adds it (back)
//   recreate NAME 0|1   delete the tag's node and add it again, same node
//                       id, holding the value, its old items' listeners
//                       taken off first: they are told nothing
//   level N             say N as the server's ServiceLevel (redundancy)
//   alarm NAME SEV MSG  make the alarm NAME (AlarmConditionType ns=URI;
//                       s=Press.NAME, source the object Press, made on
//                       first use) active and unacknowledged, Severity SEV
//                       (1..1000), Message MSG (the rest of the line): an
//                       event, a new one each time
//   normal NAME         make it inactive: an event (none if it was), still
//                       retained while unacknowledged
//   hmi-ack NAME USER COMMENT   acknowledge it from the server, ClientUserId
//                       USER, Comment COMMENT (the rest): an event (none if
//                       it was acknowledged)
//   reverse URL         reverse connect (OPC UA Part 6 §7.1.3): dial the
//                       client listening at URL (opc.tcp://HOST:PORT), send
//                       it a ReverseHello naming this server's endpoint, and
//                       dial again whenever that connection ends or a dial
//                       fails (node-opcua's ReverseConnectManager: 5 s later,
//                       doubling up to 60 s while dials fail), until quit
//   quit
// A client's Acknowledge of an alarm, once done, is told as "acknowledged
// NAME COMMENT". node-opcua drops Retain on acknowledging, active or not.
"use strict";
const fs = require("fs");
const path = require("path");
const readline = require("readline");
const { OPCUAServer, ReverseConnectManager } = require("node-opcua-server");
const { SecurityPolicy, MessageSecurityMode } = require("node-opcua-secure-channel");
const { DataType, Variant } = require("node-opcua-variant");
const { OPCUACertificateManager } = require("node-opcua-certificate-manager");
const { ownCertificate } = require("./certificate");

const APPLICATION_URI = "urn:cellwatch:test:node-opcua";

async function main() {
  const [port, pkiDir, n, uri] = process.argv.slice(2);
  const { certFile, keyFile } = await ownCertificate(pkiDir, APPLICATION_URI, "cellwatch interop node-opcua");
  const serverCertificateManager = new OPCUACertificateManager({
    rootFolder: pkiDir,
    automaticallyAcceptUnknownCertificate: false,
  });
  await serverCertificateManager.initialize();
  const server = new OPCUAServer({
    port: Number(port),
    hostname: "127.0.0.1",
    // Names in the certificate it makes for itself, checked by clients.
    alternateHostname: ["127.0.0.1", "localhost"],
    serverInfo: { applicationUri: APPLICATION_URI, productUri: "urn:cellwatch:test" },
    serverCertificateManager,
    certificateFile: certFile,
    privateKeyFile: keyFile,
    securityPolicies: [SecurityPolicy.Basic256Sha256],
    securityModes: [MessageSecurityMode.SignAndEncrypt],
    allowAnonymous: true,
    serverCapabilities: {
      // Sampling 0 is served exception-based: every change, uncoalesced.
      minSupportedSampleRate: 0,
      maxMonitoredItemsPerCall: 10000,
      operationLimits: { maxMonitoredItemsPerCall: 10000, maxNodesPerRead: 10000 },
    },
  });
  await server.initialize();
  const ns = server.engine.addressSpace.registerNamespace(uri);
  const folder = ns.addFolder(server.engine.addressSpace.rootFolder.objects, { browseName: "Plc" });
  const tags = new Map();
  const add = (name, value) => {
    const v = ns.addVariable({
      componentOf: folder, browseName: name, nodeId: `s=${name}`, dataType: "Boolean",
      minimumSamplingInterval: 0,
    });
    v.setValueFromSource(new Variant({ dataType: DataType.Boolean, value }));
    tags.set(name, v);
  };
  for (let i = 0; i < Number(n); i++) {
    add(`T${i}`, true);
  }
  // Alarms & Conditions: Press, an event notifier under Objects and an
  // event source of the Server object (HasEventSource: node-opcua wants
  // exactly that of a condition's source, HasNotifier won't do), is the
  // source of the alarms, made on demand.
  const addressSpace = server.engine.addressSpace;
  // Binds Acknowledge (i=9111) and ConditionRefresh (i=3875) on the types.
  addressSpace.installAlarmsAndConditionsService();
  const press = ns.addObject({
    organizedBy: addressSpace.rootFolder.objects, browseName: "Press", nodeId: "s=Press",
    eventNotifier: 1, eventSourceOf: addressSpace.rootFolder.objects.server,
  });
  const alarms = new Map();
  let hmiAck = false;
  const alarmOf = (name) => {
    if (!alarms.has(name)) {
      const a = ns.instantiateAlarmCondition("AlarmConditionType", {
        componentOf: press, conditionSource: press, browseName: name, nodeId: `s=Press.${name}`,
        conditionName: name, inputNode: addressSpace.resolveNodeId("i=0"),
      });
      // node-opcua would name the source "N:Press", its qualified name.
      a.setSourceName("Press");
      // Told once node-opcua has acknowledged it, events raised.
      a.on("acknowledged", (_eventId, comment) => {
        if (!hmiAck) {
          setImmediate(() => console.log(`acknowledged ${name} ${comment?.text ?? ""}`));
        }
      });
      alarms.set(name, a);
    }
    return alarms.get(name);
  };
  // Say when a subscription outlives its lifetime without publish
  // requests (a client cut off): the server drops it.
  server.on("create_session", (session) => {
    session.on("new_subscription", (subscription) => {
      subscription.on("expired", () => console.log(`expired subscription ${subscription.id}`));
    });
  });
  await server.start();
  const pem = fs.readFileSync(server.certificateFile, "utf8");
  const der = Buffer.from(pem.replace(/-----[^-]+-----/g, "").replace(/\s+/g, ""), "base64");
  const derFile = path.join(pkiDir, "server.der");
  fs.writeFileSync(derFile, der);
  console.log(`ready ${derFile}`);
  // Clients dialled (reverse connect), each by its own dial loop: what
  // OPCUAServer starts for its reverseConnect option, started on demand.
  const dialling = [];
  const rl = readline.createInterface({ input: process.stdin });
  for await (const line of rl) {
    const [cmd, name, arg] = line.trim().split(/\s+/);
    const v = tags.get(name);
    // The line's words from the K-th on, as written.
    const rest = (k) => line.trim().split(/\s+/).length > k
      ? line.trim().replace(new RegExp(`^(?:\\S+\\s+){${k}}`), "") : "";
    if (cmd === "set" && v) {
      v.setValueFromSource(new Variant({ dataType: DataType.Boolean, value: arg === "1" }));
    } else if (cmd === "toggle" && v) {
      for (let i = 0; i < Number(arg); i++) {
        v.setValueFromSource(new Variant({ dataType: DataType.Boolean, value: i % 2 === 1 }));
      }
    } else if (cmd === "delete" && v) {
      // As a changed configuration does: node-opcua tells the node's
      // monitored items (BadNodeIdInvalid) and stops them.
      server.engine.addressSpace.deleteNode(v);
      tags.delete(name);
    } else if (cmd === "recreate" && v) {
      v.removeAllListeners();
      server.engine.addressSpace.deleteNode(v);
      add(name, arg === "1");
    } else if (cmd === "add" && !v) {
      add(name, arg === "1");
    } else if (cmd === "level" && name) {
      // ServiceLevel is bound to a getter by the engine (255): bound again
      // to the level asked.
      const level = Number(name);
      const node = server.engine.addressSpace.findNode("ns=0;i=2267");
      node.bindVariable({ get: () => new Variant({ dataType: DataType.Byte, value: level }) }, true);
    } else if (cmd === "alarm" && name && Number(arg) >= 1 && Number(arg) <= 1000) {
      const a = alarmOf(name);
      a.activateAlarm();
      a.raiseNewCondition({ severity: Number(arg), message: rest(3), retain: true });
    } else if (cmd === "normal" && alarms.get(name)?.currentBranch().getActiveState()) {
      const a = alarms.get(name);
      const b = a.currentBranch();
      a.deactivateAlarm(!b.getAckedState());
      a.raiseNewCondition({ severity: b.getSeverity(), message: b.getMessage() });
    } else if (cmd === "hmi-ack" && alarms.has(name) && arg) {
      const a = alarms.get(name);
      const b = a.currentBranch();
      if (!b.getAckedState()) {
        b.setClientUserId(arg);
        hmiAck = true;
        try {
          a.acknowledgeAndAutoConfirmBranch(b, rest(3));
        } finally {
          hmiAck = false;
        }
      }
    } else if (cmd === "reverse" && name) {
      const dialer = new ReverseConnectManager({
        getDialEndpoint: () => server.endpoints[0],
        getServerUri: () => server.serverInfo.applicationUri || "",
        getEndpointUrl: () => server.getEndpointUrl(),
      }, { connections: [{ endpointUrl: name }] });
      dialer.start();
      dialling.push(dialer);
    } else if (cmd === "quit") {
      break;
    }
    console.log(`done ${line.trim()}`);
  }
  dialling.forEach((d) => d.stop());
  await server.shutdown(0);
  process.exit(0);
}
main().catch((e) => { console.error(e); process.exit(1); });
