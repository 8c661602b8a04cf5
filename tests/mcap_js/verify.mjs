// The independent reader check of teleop's session files: the official TypeScript MCAP reader
// (@mcap/core) must read the whole file, and every message must decode (protobufjs) against
// the FileDescriptorSet embedded in its channel's schema.
//
//   node verify.mjs [--stream] [--allow-truncated] [--session] [--expect EXPECTED.json] FILE
//
// Default: McapIndexedReader (footer, summary, chunk indexes; CRCs validated). --stream:
// McapStreamReader from the first byte (for files without a summary); --allow-truncated
// accepts a file that ends before its footer, counting what the complete records hold.
// Prints {"file","reader","messages","topics"} as JSON on stdout; exits 1 on any error, or
// when --expect's {"messages","topics"} differ from what was read. --session (indexed only)
// adds "session": what a Foxglove user gets from a teleop session (docs/supervisor.md
// "Sessions"): the Header's library, every Metadata record (read through the summary's
// Metadata Index), every Attachment (CRC validated; text/plain ones with their text), the
// first and last log time and each topic's, and every foxglove.Log message decoded against
// its embedded schema (level as its enum name).
import { open, readFile } from "node:fs/promises";
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import protobuf from "protobufjs";
import "protobufjs/ext/descriptor/index.js";

function parseArgs(argv) {
  const args = { stream: false, allowTruncated: false, session: false, expect: undefined, file: undefined };
  for (let i = 0; i < argv.length; ++i) {
    const a = argv[i];
    if (a === "--stream") args.stream = true;
    else if (a === "--allow-truncated") args.allowTruncated = true;
    else if (a === "--session") args.session = true;
    else if (a === "--expect") args.expect = argv[++i];
    else if (a.startsWith("--")) throw new Error(`unknown option ${a}`);
    else if (args.file === undefined) args.file = a;
    else throw new Error(`unexpected argument ${a}`);
  }
  if (args.file === undefined) {
    throw new Error("usage: node verify.mjs [--stream] [--allow-truncated] [--expect JSON] FILE");
  }
  return args;
}

// protobufjs types per schema id, built from the schema's own FileDescriptorSet.
class Decoders {
  #types = new Map();
  typeFor(schema) {
    let type = this.#types.get(schema.id);
    if (type === undefined) {
      if (schema.encoding !== "protobuf") {
        throw new Error(`schema ${schema.id} '${schema.name}' has encoding '${schema.encoding}', not protobuf`);
      }
      const root = protobuf.Root.fromDescriptor(schema.data);
      root.resolveAll();
      type = root.lookupType(schema.name);
      this.#types.set(schema.id, type);
    }
    return type;
  }
  decode(schema, channel, message) {
    const type = this.typeFor(schema);
    let decoded;
    try {
      decoded = type.decode(message.data);
    } catch (err) {
      throw new Error(`${channel.topic} message at log time ${message.logTime} (sequence ${message.sequence}) does not decode as ${schema.name}: ${err.message}`);
    }
    const problem = type.verify(decoded);
    if (problem) throw new Error(`${channel.topic} message at log time ${message.logTime}: ${problem}`);
    return type.toObject(decoded, { longs: String, enums: String });
  }
}

function tally(counts, channel, schemas, decoders, message) {
  if (channel === undefined) throw new Error(`message on unknown channel ${message.channelId}`);
  const schema = schemas.get(channel.schemaId);
  if (schema === undefined) throw new Error(`channel ${channel.topic} has unknown schema ${channel.schemaId}`);
  if (channel.messageEncoding !== "protobuf") {
    throw new Error(`channel ${channel.topic} has message encoding '${channel.messageEncoding}', not protobuf`);
  }
  const decoded = decoders.decode(schema, channel, message);
  counts.set(channel.topic, (counts.get(channel.topic) ?? 0) + 1);
  return { topic: channel.topic, schema: schema.name, decoded };
}

// What --session reports of an indexed file (see the top of this file).
class SessionFacts {
  #times = new Map();  // topic -> [first, last] log time
  logs = [];
  note(message, seen) {
    const t = this.#times.get(seen.topic);
    if (t === undefined) this.#times.set(seen.topic, [message.logTime, message.logTime]);
    else {
      if (message.logTime < t[0]) t[0] = message.logTime;
      if (message.logTime > t[1]) t[1] = message.logTime;
    }
    if (seen.schema === "foxglove.Log") {
      this.logs.push({ level: seen.decoded.level ?? "UNKNOWN", name: seen.decoded.name ?? "",
                       message: seen.decoded.message ?? "",
                       timestamp_s: String(seen.decoded.timestamp?.seconds ?? "0") });
    }
  }
  async collect(reader) {
    const metadata = {};
    for await (const m of reader.readMetadata()) metadata[m.name] = Object.fromEntries(m.metadata);
    const attachments = [];
    for await (const a of reader.readAttachments({ validateCrcs: true })) {
      const entry = { name: a.name, media_type: a.mediaType, size: a.data.length,
                      log_time: String(a.logTime) };
      if (a.mediaType.startsWith("text/")) entry.text = new TextDecoder().decode(a.data);
      attachments.push(entry);
    }
    if (reader.metadataIndexes.length !== Object.keys(metadata).length) {
      throw new Error(`${reader.metadataIndexes.length} Metadata Index records, ${Object.keys(metadata).length} metadata names read`);
    }
    const topics = {};
    let first, last;
    for (const [topic, [a, b]] of [...this.#times.entries()].sort()) {
      topics[topic] = { first_log_time: String(a), last_log_time: String(b) };
      if (first === undefined || a < first) first = a;
      if (last === undefined || b > last) last = b;
    }
    return { library: reader.header.library, profile: reader.header.profile, metadata, attachments,
             first_log_time: String(first ?? 0n), last_log_time: String(last ?? 0n), topics,
             logs: this.logs };
  }
}

async function readIndexed(file, counts, facts) {
  const handle = await open(file, "r");
  try {
    const readable = {
      size: async () => BigInt((await handle.stat()).size),
      read: async (offset, size) => {
        const buffer = new Uint8Array(Number(size));
        const { bytesRead } = await handle.read(buffer, 0, buffer.length, Number(offset));
        if (bytesRead !== buffer.length) throw new Error(`short read at offset ${offset}`);
        return buffer;
      },
    };
    const reader = await McapIndexedReader.Initialize({ readable });
    if (reader.chunkIndexes.length === 0) throw new Error("no chunk indexes in the summary");
    const decoders = new Decoders();
    let total = 0;
    let last = -1n;
    for await (const message of reader.readMessages({ validateCrcs: true })) {
      if (message.logTime < last) throw new Error(`log time went back at ${message.logTime}`);
      last = message.logTime;
      const seen = tally(counts, reader.channelsById.get(message.channelId), reader.schemasById, decoders, message);
      facts?.note(message, seen);
      ++total;
    }
    if (facts !== undefined) facts.result = await facts.collect(reader);
    if (reader.statistics === undefined) throw new Error("no Statistics record");
    if (reader.statistics.messageCount !== BigInt(total)) {
      throw new Error(`Statistics says ${reader.statistics.messageCount} messages, read ${total}`);
    }
    for (const [id, n] of reader.statistics.channelMessageCounts) {
      const topic = reader.channelsById.get(id)?.topic;
      if (BigInt(counts.get(topic) ?? 0) !== n) {
        throw new Error(`Statistics says ${n} messages on ${topic}, read ${counts.get(topic) ?? 0}`);
      }
    }
  } finally {
    await handle.close();
  }
}

async function readStream(file, counts, allowTruncated) {
  const reader = new McapStreamReader({ validateCrcs: true });
  reader.append(await readFile(file));
  const schemas = new Map();
  const channels = new Map();
  const decoders = new Decoders();
  let dataEnded = false;
  for (let record; (record = reader.nextRecord()); ) {
    switch (record.type) {
      case "Schema":
        schemas.set(record.id, record);
        break;
      case "Channel":
        channels.set(record.id, record);
        break;
      case "Message":
        if (dataEnded) throw new Error("a Message after Data End");
        tally(counts, channels.get(record.channelId), schemas, decoders, record);
        break;
      case "DataEnd":
        dataEnded = true;
        break;
      default:
        break;
    }
  }
  if (!reader.done() && !allowTruncated) {
    throw new Error(`ends before its footer (${reader.bytesRemaining()} bytes left unparsed)`);
  }
}

async function main() {
  const args = parseArgs(process.argv.slice(2));
  const counts = new Map();
  if (args.session && args.stream) throw new Error("--session reads the indexed file, not with --stream");
  const facts = args.session ? new SessionFacts() : undefined;
  try {
    if (args.stream) await readStream(args.file, counts, args.allowTruncated);
    else await readIndexed(args.file, counts, facts);
  } catch (err) {
    throw new Error(`${args.file}: ${err.message}`);
  }
  const topics = Object.fromEntries([...counts.entries()].sort(([a], [b]) => (a < b ? -1 : a > b ? 1 : 0)));
  const messages = [...counts.values()].reduce((a, b) => a + b, 0);
  const result = { file: args.file, reader: args.stream ? "stream" : "indexed", messages, topics };
  if (facts !== undefined) result.session = facts.result;
  console.log(JSON.stringify(result));
  if (args.expect !== undefined) {
    const want = JSON.parse(await readFile(args.expect, "utf8"));
    const got = JSON.stringify({ messages, topics });
    const wanted = JSON.stringify({ messages: want.messages, topics: want.topics });
    if (got !== wanted) throw new Error(`${args.file}: read ${got}, expected ${wanted}`);
  }
}

main().catch((err) => {
  console.error(`verify.mjs: ${err.message}`);
  process.exit(1);
});
