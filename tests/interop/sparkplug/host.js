// An independent Sparkplug B host for cellwatch's tests. It subscribes to
// every Sparkplug topic of the broker at argv[2] and prints each message as
// one JSON line on stdout, its payload decoded by Eclipse Tahu's JavaScript
// payload library (STATE payloads as text). Each JSON line on stdin is a
// message to publish: {"topic", "payload"} (a Sparkplug payload encoded by
// the same library) or {"topic", "text", "retain"} (raw text, for STATE).
"use strict";
const readline = require("readline");
const Long = require("long");
const mqtt = require("mqtt");
const sparkplug = require("sparkplug-payload").get("spBv1.0");

const say = (o) =>
  process.stdout.write(
    JSON.stringify(o, (_, v) => (Long.isLong(v) ? v.toNumber() : v)) + "\n"
  );

const client = mqtt.connect(process.argv[2], {
  clientId: "tahu-host-" + process.pid,
  clean: true,
  reconnectPeriod: 200,
});
client.on("connect", () => {
  client.subscribe("spBv1.0/#", { qos: 1 }, (err) => {
    if (err) {
      say({ error: String(err) });
    } else {
      say({ subscribed: true });
    }
  });
});
// The broker away (a test restarts it) is said, not an error: the client
// connects again by itself.
client.on("error", (err) =>
  say(
    ["ECONNREFUSED", "ECONNRESET"].includes(err.code)
      ? { unreachable: String(err) }
      : { error: String(err) }
  )
);
client.on("message", (topic, payload) => {
  if (topic.startsWith("spBv1.0/STATE/")) {
    say({ topic, text: payload.toString() });
    return;
  }
  try {
    say({ topic, payload: sparkplug.decodePayload(payload) });
  } catch (err) {
    say({ topic, error: String(err) });
  }
});
readline.createInterface({ input: process.stdin }).on("line", (line) => {
  const m = JSON.parse(line);
  const body =
    m.payload !== undefined ? sparkplug.encodePayload(m.payload) : m.text;
  client.publish(m.topic, body, { qos: 1, retain: !!m.retain }, (err) => {
    say({ published: m.topic, error: err ? String(err) : undefined });
  });
});
