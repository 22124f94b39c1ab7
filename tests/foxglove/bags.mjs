// The recorder's bags as the Foxglove app opens them: each .mcap file of each bag directory read
// with @mcap/core's indexed reader (zstd chunks through fzstd, the decompressor Foxglove's own
// MCAP tooling uses in JavaScript), every message decoded with @foxglove/rosmsg2-serialization by
// the ros2msg schema stored in the file. tests/python/test_foxglove.py compares the counts with
// the bag's metadata.yaml.
//
//   node bags.mjs BAG_DIR...   prints {BAG_DIR: {"files": n, "counts": {topic: n}, "errors": [...]}}

import { readFileSync, readdirSync } from "node:fs";
import { join } from "node:path";
import { McapIndexedReader } from "@mcap/core";
import rosmsg from "@foxglove/rosmsg";
import serialization from "@foxglove/rosmsg2-serialization";
import { decompress } from "fzstd";

// (CommonJS packages: their exports come as one object)
const { parse } = rosmsg;
const { MessageReader } = serialization;

const decompressHandlers = { zstd: (buffer) => decompress(buffer) };

function readable(bytes) {
  return {
    size: async () => BigInt(bytes.byteLength),
    read: async (offset, size) => bytes.subarray(Number(offset), Number(offset + size)),
  };
}

async function readBag(dir) {
  const files = readdirSync(dir).filter((f) => f.endsWith(".mcap")).sort();
  const counts = {};
  const errors = [];
  for (const file of files) {
    const reader = await McapIndexedReader.Initialize({
      readable: readable(new Uint8Array(readFileSync(join(dir, file)))),
      decompressHandlers,
    });
    const readers = new Map(); // schema id -> MessageReader
    for (const [id, schema] of reader.schemasById) {
      if (schema.encoding !== "ros2msg") {
        errors.push(`${file}: schema ${schema.name} is ${schema.encoding}, not ros2msg`);
        continue;
      }
      const text = new TextDecoder().decode(schema.data);
      readers.set(id, new MessageReader(parse(text, { ros2: true })));
    }
    for await (const message of reader.readMessages()) {
      const channel = reader.channelsById.get(message.channelId);
      const decoder = readers.get(channel.schemaId);
      try {
        if (!decoder) throw new Error(`no ros2msg schema for channel ${channel.topic}`);
        decoder.readMessage(message.data);
        counts[channel.topic] = (counts[channel.topic] ?? 0) + 1;
      } catch (error) {
        errors.push(`${file}: ${channel.topic} at ${message.logTime}: ${error}`);
      }
    }
  }
  return { files: files.length, counts, errors };
}

const report = {};
for (const dir of process.argv.slice(2)) report[dir] = await readBag(dir);
process.stdout.write(JSON.stringify(report) + "\n");
