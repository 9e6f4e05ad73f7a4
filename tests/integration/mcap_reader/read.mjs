// An independent reader of phytrace-edge hand-carry files: the MCAP project's own
// TypeScript libraries read each file given, and Ajv checks every message against its
// channel's JSON Schema. Prints one JSON document per file; exits 1 if a file cannot be
// read. Used by tests/integration/test_handcarry_mcap_reader.py (npm packages in
// package.json).
import { open } from "node:fs/promises";
import { McapIndexedReader } from "@mcap/core";
import { FileHandleReadable } from "@mcap/nodejs";
import { loadDecompressHandlers } from "@mcap/support";
import Ajv from "ajv";

const decompressHandlers = await loadDecompressHandlers();
const text = new TextDecoder();

async function readFile(path) {
  const handle = await open(path, "r");
  try {
    const reader = await McapIndexedReader.Initialize({
      readable: new FileHandleReadable(handle),
      decompressHandlers,
    });
    const ajv = new Ajv({ allErrors: false, strict: false });
    const validators = new Map();
    const channels = [];
    for (const channel of reader.channelsById.values()) {
      const schema = reader.schemasById.get(channel.schemaId);
      validators.set(channel.id, ajv.compile(JSON.parse(text.decode(schema.data))));
      channels.push({
        topic: channel.topic,
        messageEncoding: channel.messageEncoding,
        schemaName: schema.name,
        schemaEncoding: schema.encoding,
      });
    }
    const perTopic = {};
    const invalid = [];
    let messages = 0;
    let logTimeMismatches = 0;
    for await (const message of reader.readMessages({ validateCrcs: true })) {
      messages += 1;
      const channel = reader.channelsById.get(message.channelId);
      perTopic[channel.topic] = (perTopic[channel.topic] ?? 0) + 1;
      const event = JSON.parse(text.decode(message.data));
      const validate = validators.get(message.channelId);
      if (!validate(event)) {
        invalid.push({ event_id: event.event_id, errors: validate.errors.slice(0, 2) });
      }
      const capturedNs = BigInt(Date.parse(event.captured_at)) * 1000000n;
      if (capturedNs !== message.logTime) logTimeMismatches += 1;
    }
    const metadata = {};
    for await (const record of reader.readMetadata()) {
      metadata[record.name] = Object.fromEntries(record.metadata);
    }
    return {
      file: path,
      profile: reader.header.profile,
      library: reader.header.library,
      channels,
      statisticsMessageCount: Number(reader.statistics?.messageCount ?? -1),
      messages,
      perTopic,
      invalid: invalid.slice(0, 5),
      invalidCount: invalid.length,
      logTimeMismatches,
      metadata,
    };
  } finally {
    await handle.close();
  }
}

let failed = false;
for (const path of process.argv.slice(2)) {
  try {
    console.log(JSON.stringify(await readFile(path)));
  } catch (error) {
    failed = true;
    console.log(JSON.stringify({ file: path, error: String(error) }));
  }
}
process.exit(failed ? 1 : 0);
