// A headless Foxglove viewer of the node's live view, with Foxglove's own client libraries:
// @foxglove/ws-protocol speaks the WebSocket protocol, @foxglove/rosmsg parses each channel's
// advertised ros2msg schema and @foxglove/rosmsg2-serialization decodes its CDR messages, as the
// Foxglove app does (the scene's protobuf messages: protobufjs, as the app decodes them). tests/python/test_foxglove.py drives it; it reports on stdout, one JSON
// object a line, and ends when its stdin closes (or, in `stall` mode, when the server drops it).
//
//   node live.mjs record URL   every channel subscribed as advertised; each message decoded:
//                              {"event":"message","topic","schema","log_time","data","value"}
//   node live.mjs count URL    as `record`, but reports only the messages decoded per topic when
//                              its stdin closes: {"event":"counts","counts":{topic: n}} (for benches)
//   node live.mjs stall URL    every channel subscribed, then the socket is no longer read
//                              (a viewer that hangs): {"event":"stalled"} once it stops reading
//   node live.mjs garbage URL  malformed and unsupported client messages, then what the server
//                              answered: {"event":"status",...}; {"event":"sent","count"}
//   node live.mjs params URL   every parameter, then a set request for `seed`: each answer as
//                              {"event":"parameters","id","parameters"}
//   node live.mjs reset URL SERVICE SEED   as `record`, and calls the service SERVICE (a line's
//                              ResetLine) with SEED, then with bytes that are no request:
//                              {"event":"service_response","value"}, {"event":"service_failure","message"}
//
// Other events: {"event":"open"}, {"event":"advertise","topic","schema","encoding","schemaEncoding"},
// {"event":"subscribed","topic"}, {"event":"time","time"}, {"event":"decode_error","topic","error"},
// {"event":"close"}.

import wsProtocol from "@foxglove/ws-protocol";
import rosmsg from "@foxglove/rosmsg";
import serialization from "@foxglove/rosmsg2-serialization";
import protobuf from "protobufjs";
import descriptor from "protobufjs/ext/descriptor/index.js";
import WebSocket from "ws";

// (CommonJS packages: their exports come as one object)
const { FoxgloveClient } = wsProtocol;
const { parse } = rosmsg;
const { MessageReader } = serialization;

const [mode, url] = process.argv.slice(2);
const [serviceName, seed] = process.argv.slice(4);
if (!["record", "count", "stall", "garbage", "params", "reset"].includes(mode) || !url || (mode === "reset" && !seed)) {
  process.stderr.write("usage: node live.mjs record|count|stall|garbage|params URL | reset URL SERVICE SEED\n");
  process.exit(2);
}

// 64-bit integers come as bigints, arrays of numbers as typed arrays: JSON gets numbers and lists
// (a bigint beyond 2^53 as a decimal string).
const plain = (v) => (typeof v === "bigint" ? (Number.isSafeInteger(Number(v)) ? Number(v) : v.toString()) : v);
const say = (obj) =>
  process.stdout.write(
    JSON.stringify(obj, (_k, v) => (ArrayBuffer.isView(v) ? Array.from(v, plain) : plain(v))) + "\n",
  );

// The Foxglove SDK's servers (the node's, crate foxglove 0.30) speak the protocol under the name
// `foxglove.sdk.v1`, the same messages as ws-protocol's `foxglove.websocket.v1`, which they no
// longer accept by that name; the Foxglove app offers both.
const ws = new WebSocket(url, ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map(); // subscription id -> {topic, schema, reader}

client.on("open", () => {
  say({ event: "open" });
  if (mode === "garbage") sendGarbage();
  if (mode === "params") {
    client.getParameters([], "all");
    client.setParameters([{ name: "seed", value: 12345 }], "set-seed");
  }
});
client.on("advertiseServices", (services) => {
  for (const service of services) {
    say({ event: "advertise_service", name: service.name, type: service.type });
    if (mode !== "reset" || service.name !== serviceName) continue;
    // The request encoded by the advertised schema, as the Foxglove app's service call panel does.
    const request = new serialization.MessageWriter(parse(service.request.schema, { ros2: true }));
    const response = new MessageReader(parse(service.response.schema, { ros2: true }));
    responses.set(service.id, response);
    const data = request.writeMessage({ has_seed: true, seed: BigInt(seed) });
    client.sendServiceCallRequest({ serviceId: service.id, callId: 1, encoding: "cdr", data });
    client.sendServiceCallRequest({ serviceId: service.id, callId: 2, encoding: "cdr", data: new Uint8Array([1, 2]) });
  }
});
const responses = new Map(); // service id -> response reader
client.on("serviceCallResponse", ({ serviceId, callId, data }) => {
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  say({ event: "service_response", callId, value: responses.get(serviceId).readMessage(bytes) });
});
client.on("serviceCallFailure", ({ callId, message }) => say({ event: "service_failure", callId, message }));
client.on("parameterValues", ({ id, parameters }) => say({ event: "parameters", id, parameters }));
client.on("error", (error) => say({ event: "error", error: String(error?.message ?? error) }));
client.on("close", () => {
  say({ event: "close" });
  process.stdout.write("", () => process.exit(0));
});
client.on("status", (s) => say({ event: "status", level: s.level, message: s.message }));
client.on("time", (t) => say({ event: "time", time: t.timestamp }));

client.on("advertise", (advertised) => {
  for (const channel of advertised) {
    say({
      event: "advertise",
      topic: channel.topic,
      schema: channel.schemaName,
      encoding: channel.encoding,
      schemaEncoding: channel.schemaEncoding,
    });
    if (mode === "garbage" || mode === "params") continue;
    let reader;
    try {
      reader = decoder(channel);
    } catch (error) {
      say({ event: "decode_error", topic: channel.topic, error: `schema: ${error}` });
      continue;
    }
    const id = client.subscribe(channel.id);
    channels.set(id, { topic: channel.topic, schema: channel.schemaName, reader });
    say({ event: "subscribed", topic: channel.topic });
  }
  if (mode === "stall" && !stalled) {
    // Stop reading the socket: the server's writes pile up in the kernel's buffers, then in
    // the server's queue for this viewer.
    stalled = true;
    ws._socket.pause();
    say({ event: "stalled" });
  }
});
let stalled = false;
const counts = {}; // topic -> messages decoded (`count` mode)

client.on("message", ({ subscriptionId, timestamp, data }) => {
  const channel = channels.get(subscriptionId);
  if (!channel) return;
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  let value;
  try {
    value = channel.reader.readMessage(bytes);
  } catch (error) {
    say({ event: "decode_error", topic: channel.topic, error: String(error) });
    return;
  }
  if (mode === "count") {
    counts[channel.topic] = (counts[channel.topic] ?? 0) + 1;
    return;
  }
  say({
    event: "message",
    topic: channel.topic,
    schema: channel.schema,
    log_time: timestamp,
    data: Buffer.from(bytes).toString("base64"),
    value,
  });
});

// A channel's decoder by its advertised schema, as the Foxglove app picks it: ros2msg (CDR) with
// @foxglove/rosmsg2-serialization, protobuf (the scene: a base64 FileDescriptorSet) with protobufjs.
function decoder(channel) {
  if (channel.schemaEncoding === "ros2msg" && channel.encoding === "cdr") {
    return new MessageReader(parse(channel.schema, { ros2: true }));
  }
  if (channel.schemaEncoding === "protobuf" && channel.encoding === "protobuf") {
    const set = descriptor.FileDescriptorSet.decode(Buffer.from(channel.schema, "base64"));
    const type = protobuf.Root.fromDescriptor(set).lookupType(channel.schemaName);
    return {
      readMessage: (bytes) => type.toObject(type.decode(bytes), { longs: Number, enums: String, defaults: true }),
    };
  }
  throw new Error(`no decoder for ${channel.encoding} messages with a ${channel.schemaEncoding} schema`);
}

// What a confused or hostile viewer sends: none of it may hurt the line.
function sendGarbage() {
  const raw = [
    "not json at all",
    "{}",
    JSON.stringify({ op: "no-such-op" }),
    JSON.stringify({ op: "subscribe", subscriptions: [{ id: 1, channelId: 987654 }] }),
    JSON.stringify({ op: "subscribe", subscriptions: "nonsense" }),
    JSON.stringify({ op: "unsubscribe", subscriptionIds: [424242] }),
    JSON.stringify({ op: "getParameters", parameterNames: ["seed"], id: "x" }),
    JSON.stringify({ op: "callService", serviceId: 5, callId: 1, encoding: "cdr", data: "" }),
    JSON.stringify({ op: "advertise", channels: [{ id: 1, topic: "/cmd/speed", encoding: "cdr", schemaName: "x" }] }),
  ];
  for (const text of raw) ws.send(text);
  ws.send(Buffer.from([0x01, 0xff, 0xff, 0xff, 0xff])); // binary: a message for no advertised channel
  ws.send(Buffer.from([0x7f])); // binary: unknown opcode
  // A flood of malformed requests.
  for (let i = 0; i < 200; i++) ws.send(JSON.stringify({ op: "subscribe", subscriptions: [{ id: i }] }));
  say({ event: "sent", count: raw.length + 2 + 200 });
}

process.stdin.on("data", () => {});
process.stdin.on("end", () => {
  if (mode === "count") say({ event: "counts", counts });
  if (mode === "stall") ws._socket.destroy();
  client.close();
  // Exit once what was written has gone out (a line cut short would be unreadable).
  process.stdout.write("", () => process.exit(0));
});
