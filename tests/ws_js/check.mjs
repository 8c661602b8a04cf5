// The live bridge (teleopctl bridge) read by the official Foxglove WebSocket client
// (@foxglove/ws-protocol over the `ws` package): connects with the foxglove.websocket.v1
// subprotocol, records serverInfo and every advertised channel, subscribes to the topics
// named, decodes each message with protobufjs against the schema the channel advertised (a
// base64 FileDescriptorSet), and after WINDOW_S seconds of messages on every subscribed topic
// prints one JSON summary on stdout for the C++ test to judge (tests/integration/
// test_bridge_live.cpp). A topic named TOPIC:N is instead read, every message kept, until N
// messages arrived on it and every other topic had its window (for channels that speak when
// something happens: the configuration in force, the parameter changes). The first message on
// each topic is said on stderr ("first message on TOPIC"), so a test can act once the client
// has it. Exit 0 once the summary is printed, 1
// on a protocol or decode error, 2 on a timeout (the summary then says what was missing).
//
//   [WS_CHECK_BOUND_S=S] node check.mjs ws://127.0.0.1:PORT WINDOW_S TOPIC[:N] [TOPIC[:N]...]
import FoxgloveClientModule from "@foxglove/ws-protocol";
import protobuf from "protobufjs";
import "protobufjs/ext/descriptor/index.js";
import WebSocket from "ws";

const FoxgloveClient = FoxgloveClientModule.FoxgloveClient ?? FoxgloveClientModule.default;
const [url, windowArg, ...topicArgs] = process.argv.slice(2);
const windowS = Number(windowArg);
const counted = new Map(); // topic -> messages to wait for (TOPIC:N)
const topics = topicArgs.map((arg) => {
  const colon = arg.lastIndexOf(":");
  if (colon < 0) return arg;
  counted.set(arg.slice(0, colon), Number(arg.slice(colon + 1)));
  return arg.slice(0, colon);
});
if (!url || !(windowS > 0) || topics.length === 0 ||
    [...counted.values()].some((n) => !(Number.isInteger(n) && n > 0))) {
  console.error("usage: node check.mjs ws://HOST:PORT WINDOW_S TOPIC[:N] [TOPIC[:N]...]");
  process.exit(2);
}

const summary = { serverInfo: null, channels: [], topics: {}, errors: [] };
const subscriptions = new Map(); // subscription id -> { topic, type }
const decoders = new Map(); // channel id -> protobufjs Type

function typeFor(channel) {
  if (channel.encoding !== "protobuf" || channel.schemaEncoding !== "protobuf") {
    throw new Error(`${channel.topic}: encoding ${channel.encoding}/${channel.schemaEncoding}`);
  }
  const bytes = Buffer.from(channel.schema, "base64");
  const set = protobuf.descriptor.FileDescriptorSet.decode(bytes);
  return protobuf.Root.fromDescriptor(set).lookupType(channel.schemaName);
}

// Numbers from a decoded message: longs as numbers (ns since the epoch fit a double to ~0.25 us).
const num = (v) => (v === undefined || v === null ? 0 : Number(v));

function stats(topic) {
  if (!summary.topics[topic]) {
    summary.topics[topic] = {
      count: 0, first_receive_ns: null, last_receive_ns: null, receive_nondecreasing: true,
      first_sequence: null, last_sequence: null, sequence_steps_not_one: 0,
      position_m: { min: Infinity, max: -Infinity, sum: 0 },
      force_N: { min: Infinity, max: -Infinity, sum: 0 },
      modes: {}, last: null,
    };
  }
  return summary.topics[topic];
}

function take(topic, receiveNs, msg) {
  const s = stats(topic);
  s.count += 1;
  if (s.last_receive_ns !== null && receiveNs < s.last_receive_ns) s.receive_nondecreasing = false;
  if (s.first_receive_ns === null) s.first_receive_ns = receiveNs;
  s.last_receive_ns = receiveNs;
  if (topic.endsWith("/cycle")) {
    const seq = num(msg.sequence);
    if (s.last_sequence !== null && seq !== s.last_sequence + 1) s.sequence_steps_not_one += 1;
    if (s.first_sequence === null) s.first_sequence = seq;
    s.last_sequence = seq;
    for (const key of ["position_m", "force_N"]) {
      const v = num(msg[key]);
      s[key].min = Math.min(s[key].min, v);
      s[key].max = Math.max(s[key].max, v);
      s[key].sum += v;
    }
    const mode = String(msg.mode);
    s.modes[mode] = (s.modes[mode] ?? 0) + 1;
  }
  s.last = msg;
  // Every message of the channels that speak when something happens.
  if (!topic.endsWith("/cycle") && !topic.endsWith("/telemetry") &&
      topic !== "/supervisor/status") {
    s.all = s.all ?? [];
    if (s.all.length < 200) s.all.push(msg);
  }
}

let finished = false;
function finish(code) {
  if (finished) return;
  finished = true;
  for (const s of Object.values(summary.topics)) {
    for (const key of ["position_m", "force_N"]) {
      s[key].mean = s.count > 0 ? s[key].sum / s.count : null;
      if (!Number.isFinite(s[key].min)) s[key].min = null;
      if (!Number.isFinite(s[key].max)) s[key].max = null;
    }
  }
  // Exit once written: a pipe's stdout is asynchronous, and exit() would cut it short.
  process.stdout.write(JSON.stringify(summary) + "\n", () => process.exit(code));
}

const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const started = new Map(); // topic -> performance.now() of its first message
// The bound: WS_CHECK_BOUND_S seconds if set, else the window plus 20 s.
const boundS = Number(process.env.WS_CHECK_BOUND_S ?? windowS + 20);
const timeout = setTimeout(() => {
  const short = topics.filter((t) => counted.has(t)
    ? (summary.topics[t]?.count ?? 0) < counted.get(t) : !started.has(t));
  summary.errors.push(`timeout: not ${windowS} s of messages (or the N of TOPIC:N) on every ` +
                      `topic within ${boundS} s; short: ${short.join(" ")}`);
  finish(2);
}, boundS * 1000);

client.on("error", (e) => {
  summary.errors.push(`client error: ${e?.message ?? e}`);
  clearTimeout(timeout);
  finish(1);
});
client.on("serverInfo", (info) => {
  summary.serverInfo = info;
  summary.subprotocol = ws.protocol;
});
client.on("status", (st) => summary.errors.push(`status ${st.level}: ${st.message}`));
client.on("advertise", (channels) => {
  for (const ch of channels) {
    summary.channels.push({
      id: ch.id, topic: ch.topic, encoding: ch.encoding, schemaName: ch.schemaName,
      schemaEncoding: ch.schemaEncoding, schemaBytes: Buffer.from(ch.schema, "base64").length,
    });
    if (!topics.includes(ch.topic)) continue;
    try {
      decoders.set(ch.id, typeFor(ch));
    } catch (e) {
      summary.errors.push(`schema of ${ch.topic}: ${e.message}`);
      clearTimeout(timeout);
      finish(1);
    }
    subscriptions.set(client.subscribe(ch.id), { topic: ch.topic, channel: ch.id });
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const sub = subscriptions.get(subscriptionId);
  if (!sub) {
    summary.errors.push(`message for unknown subscription ${subscriptionId}`);
    return;
  }
  let msg;
  try {
    const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
    msg = decoders.get(sub.channel).toObject(decoders.get(sub.channel).decode(bytes), {
      longs: String, enums: String, defaults: true,
    });
  } catch (e) {
    summary.errors.push(`decode on ${sub.topic}: ${e.message}`);
    clearTimeout(timeout);
    finish(1);
    return;
  }
  const now = performance.now();
  if (!started.has(sub.topic)) {
    started.set(sub.topic, now);
    console.error(`first message on ${sub.topic}`);
  }
  if (counted.has(sub.topic) || now - started.get(sub.topic) <= windowS * 1000) {
    take(sub.topic, Number(timestamp), msg);
  }
  checkDone();
});

// Done once every topic has had WINDOW_S seconds since its first message, or its N messages
// (checked on each message and every 50 ms, for topics that go quiet such as the alarms).
function checkDone() {
  const now = performance.now();
  const done = (t) => counted.has(t)
    ? (summary.topics[t]?.count ?? 0) >= counted.get(t)
    : started.has(t) && now - started.get(t) > windowS * 1000;
  if (topics.every(done)) {
    clearTimeout(timeout);
    client.close();
    finish(0);
  }
}
setInterval(checkDone, 50);
