// A Foxglove WebSocket client that is not ours, for tests/live: the protocol's own npm client
// (@foxglove/ws-protocol's FoxgloveClient over `ws`) and Foxglove's ROS 2 CDR decoder
// (@foxglove/rosmsg2-serialization, definitions parsed by @foxglove/rosmsg).
//
//   node client.js '{"url": "ws://127.0.0.1:8765", "topics": ["/joint_states"], ...}'
//
// Options (one JSON argument): url; topics to subscribe to (all advertised when "*");
// garbage: frames of junk sent right after serverInfo; paused: stop reading the socket once
// subscribed (a slow client); brief: print only topic, sizes and times of each message;
// quiet (with brief): print only the first 10 messages of each topic, and the count of each
// topic's messages when the connection closes (a benchmark's clients that must not cost the
// process reading them anything per message);
// fetch: URIs to fetch (fetchAsset) once connected; fetchMeshes: fetch every mesh the
// /robot_description it receives names (as Foxglove's 3D panel does); publish: {topic,
// encoding ("json" or "cdr"), schemaName, rateHz, count, linear, angular}: advertise and
// publish a Twist `count` times at `rateHz` (as Foxglove's Teleop panel does), once the
// server declares clientPublish; with `message` (an object) and `definition` (its ros2msg
// text, for cdr) any other message instead; `definition: "advertised"`: the definition of
// the server's channel of the same schemaName, waited for (as Foxglove's Publish panel learns
// a datatype only from what the server advertises); `publishes`: a list of such specs.
// calls: [{service, encoding, request, delayMs}]: call each advertised service by name
// (as Foxglove's Call Service panel does), the request in json or cdr (from the service's
// request schema), the response decoded likewise.
// It prints one JSON object per line: serverInfo, advertise, message (decoded), status,
// close, error; it runs until stdin closes or the server closes the connection.
"use strict";

const { FoxgloveClient } = require("@foxglove/ws-protocol");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader, MessageWriter } = require("@foxglove/rosmsg2-serialization");
const WebSocket = require("ws");
const { createHash } = require("crypto");

const options = JSON.parse(process.argv[2]);

function plain(value) {
  if (typeof value === "bigint") return Number(value);
  if (ArrayBuffer.isView(value)) {
    if (value instanceof Uint8Array) return { bytes: value.length, head: Array.from(value.slice(0, 4)) };
    return Array.from(value, plain);
  }
  if (Array.isArray(value)) return value.map(plain);
  if (value !== null && typeof value === "object") {
    const out = {};
    for (const [key, item] of Object.entries(value)) out[key] = plain(item);
    return out;
  }
  if (typeof value === "number" && !Number.isFinite(value)) return String(value);
  return value;
}

function print(object) {
  process.stdout.write(JSON.stringify(object) + "\n");
}

const ws = new WebSocket(options.url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map();
const subscriptions = new Map();
const fetches = new Map();
let nextRequest = 1;
let meshesAsked = false;

function fetchAsset(uri) {
  const id = nextRequest++;
  fetches.set(id, uri);
  client.fetchAsset(uri, id);
}

client.on("serverInfo", (info) => {
  print({ event: "serverInfo", name: info.name, capabilities: info.capabilities, protocol: ws.protocol });
  for (const uri of options.fetch || []) fetchAsset(uri);
  if (info.capabilities.includes("clientPublish")) {
    for (const spec of [options.publish, ...(options.publishes || [])]) {
      if (!spec) continue;
      if (spec.definition === "advertised") pending.push(spec);
      else publish(spec);
    }
    publishPending();
  }
  for (let i = 0; i < (options.garbage || 0); i++) {
    ws.send(i % 2 === 0 ? `not json ${i}` : Buffer.from([0xff, 0x00, i & 0xff]));
  }
});

const TWIST = "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n" +
  "================================================================================\n" +
  "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n";

function publish(spec) {
  const channel = client.advertise({ topic: spec.topic, encoding: spec.encoding, schemaName: spec.schemaName });
  const writer = new MessageWriter(parse(spec.definition || TWIST, { ros2: true }));
  const message = spec.message || {
    linear: { x: spec.linear, y: 0, z: 0 },
    angular: { x: 0, y: 0, z: spec.angular },
  };
  const encode = (m) => (spec.encoding === "cdr" ? writer.writeMessage(m) : new TextEncoder().encode(JSON.stringify(m)));
  const data = encode(message);
  // `alternate`: every second Twist's linear.x (a stream whose every message is news).
  const other = spec.alternate === undefined
    ? data
    : encode({ ...message, linear: { ...message.linear, x: spec.alternate } });
  let sent = 0;
  const send = () => {
    client.sendMessage(channel, sent % 2 === 0 ? data : other);
    sent += 1;
    print({ event: "published", topic: spec.topic, n: sent, local_ms: performance.timeOrigin + performance.now() });
    if (sent >= spec.count) {
      clearInterval(timer);
      if (spec.unadvertise) client.unadvertise(channel);
    }
  };
  const timer = setInterval(send, 1000 / spec.rateHz);
  send();
}

const pending = [];
const advertisedSchemas = new Map();

function publishPending() {
  for (let i = pending.length - 1; i >= 0; i--) {
    const schema = advertisedSchemas.get(pending[i].schemaName);
    if (schema === undefined) continue;
    const spec = { ...pending[i], definition: schema };
    pending.splice(i, 1);
    print({ event: "definition", schemaName: spec.schemaName });
    publish(spec);
  }
}

client.on("advertise", (advertised) => {
  for (const channel of advertised) advertisedSchemas.set(channel.schemaName, channel.schema);
  publishPending();
  for (const channel of advertised) {
    let reader = null;
    try {
      reader = new MessageReader(parse(channel.schema, { ros2: true }));
    } catch (error) {
      print({ event: "error", message: `${channel.topic}: ${error.message}` });
    }
    channels.set(channel.id, { channel, reader });
  }
  print({ event: "advertise", topics: advertised.map((c) => [c.topic, c.schemaName, c.encoding]) });
  const wanted = options.topics || [];
  for (const channel of advertised) {
    if (wanted.includes("*") || wanted.includes(channel.topic)) {
      subscriptions.set(client.subscribe(channel.id), channels.get(channel.id));
    }
  }
  if (options.paused && subscriptions.size > 0) {
    ws.pause();
    print({ event: "paused" });
  }
});

const counts = {};

client.on("message", ({ subscriptionId, timestamp, data }) => {
  const localMs = performance.timeOrigin + performance.now();
  const entry = subscriptions.get(subscriptionId);
  if (!entry) {
    print({ event: "error", message: `message on unknown subscription ${subscriptionId}` });
    return;
  }
  const topic = entry.channel.topic;
  counts[topic] = (counts[topic] || 0) + 1;
  if (options.quiet && counts[topic] > 10) return;
  const out = {
    event: "message",
    topic: entry.channel.topic,
    receive_ns: String(timestamp),
    local_ms: localMs,
    bytes: data.byteLength,
  };
  if (!options.brief) {
    const decoded = entry.reader.readMessage(data);
    out.trailing = entry.reader.lastReadHadTrailingBytes();
    out.decoded = plain(decoded);
    if (options.fetchMeshes && entry.channel.topic === "/robot_description" && !meshesAsked) {
      meshesAsked = true;
      for (const match of decoded.data.matchAll(/<mesh[^>]*filename="([^"]*)"/g)) fetchAsset(match[1]);
    }
  }
  print(out);
});

client.on("fetchAssetResponse", (response) => {
  const out = { event: "asset", requestId: response.requestId, uri: fetches.get(response.requestId), status: response.status };
  if (response.status === 0) {
    const bytes = new Uint8Array(response.data.buffer, response.data.byteOffset, response.data.byteLength);
    out.bytes = bytes.length;
    out.sha256 = createHash("sha256").update(bytes).digest("hex");
  } else {
    out.error = response.error;
  }
  print(out);
});

const services = new Map();
let nextCall = 1;

client.on("advertiseServices", (advertised) => {
  for (const service of advertised) services.set(service.name, service);
  print({ event: "services", services: advertised.map((s) => [s.name, s.type, s.request && s.request.schemaName]) });
  for (const call of options.calls || []) {
    const service = services.get(call.service);
    if (!service) continue;
    setTimeout(() => callService(service, call), call.delayMs || 0);
  }
});

function callService(service, call) {
  const callId = nextCall++;
  const data = call.encoding === "cdr"
    ? new MessageWriter(parse(service.request.schema, { ros2: true })).writeMessage(call.request)
    : new TextEncoder().encode(JSON.stringify(call.request));
  client.sendServiceCallRequest({ serviceId: service.id, callId, encoding: call.encoding, data });
  print({ event: "called", service: service.name, callId, local_ms: performance.timeOrigin + performance.now() });
}

client.on("serviceCallResponse", (response) => {
  const service = [...services.values()].find((s) => s.id === response.serviceId);
  const out = { event: "serviceResponse", service: service && service.name, callId: response.callId, encoding: response.encoding };
  if (response.encoding === "cdr") {
    out.decoded = plain(new MessageReader(parse(service.response.schema, { ros2: true })).readMessage(response.data));
  } else {
    out.decoded = JSON.parse(new TextDecoder().decode(response.data));
  }
  print(out);
});

client.on("serviceCallFailure", (failure) => print({ event: "serviceFailure", callId: failure.callId, message: failure.message }));

client.on("status", (status) => print({ event: "status", level: status.level, message: status.message }));
client.on("error", (error) => print({ event: "error", message: String(error && error.message) }));
client.on("close", (event) => {
  if (options.quiet) print({ event: "counts", counts });
  print({ event: "close", code: event.code, reason: String(event.reason || "") });
  process.exit(0);
});

process.stdin.on("data", () => {});
process.stdin.on("end", () => {
  ws.close();
  setTimeout(() => process.exit(0), 2000).unref();
});
