// Reads every message of a Strata MCAP log the way Foxglove does: the summary and chunk
// indexes with @mcap/core, each CDR message with its channel's OMG IDL schema through
// @foxglove/omgidl-serialization. Prints one JSON line: messages decoded per topic kind, the
// self-describing messages counted aside, and every error met.
"use strict";
const fs = require("fs");
const { McapIndexedReader } = require("@mcap/core");
const { parseIDL } = require("@foxglove/omgidl-parser");
const { MessageReader } = require("@foxglove/omgidl-serialization");
const { decompress } = require("fzstd");

async function main(path) {
  const fd = fs.openSync(path, "r");
  const size = BigInt(fs.fstatSync(fd).size);
  const readable = {
    size: async () => size,
    read: async (offset, length) => {
      const buffer = Buffer.alloc(Number(length));
      fs.readSync(fd, buffer, 0, Number(length), Number(offset));
      return buffer;
    },
  };
  const reader = await McapIndexedReader.Initialize({
    readable,
    decompressHandlers: { zstd: (data, size) => decompress(data, new Uint8Array(Number(size))) },
  });
  const readers = new Map();
  const decoded = {};
  const selfDescribing = {};
  const errors = [];
  const samples = {};
  for await (const message of reader.readMessages()) {
    const channel = reader.channelsById.get(message.channelId);
    const kind = channel.topic.replace(/^(home|away|t\d+)\/\d+\//, "");
    if (channel.messageEncoding !== "cdr") {
      selfDescribing[kind] = (selfDescribing[kind] || 0) + 1;
      continue;
    }
    let messageReader = readers.get(channel.schemaId);
    if (messageReader === undefined) {
      const schema = reader.schemasById.get(channel.schemaId);
      try {
        if (schema.encoding !== "omgidl") throw new Error(`schema encoding ${schema.encoding}`);
        messageReader = new MessageReader(schema.name, parseIDL(new TextDecoder().decode(schema.data)));
      } catch (error) {
        messageReader = error;
      }
      readers.set(channel.schemaId, messageReader);
    }
    if (messageReader instanceof Error) {
      errors.push(`${channel.topic}: schema: ${messageReader.message}`);
      continue;
    }
    try {
      const value = messageReader.readMessage(message.data);
      decoded[kind] = (decoded[kind] || 0) + 1;
      if (!(kind in samples)) samples[kind] = value;
    } catch (error) {
      errors.push(`${channel.topic} #${message.sequence}: ${error.message}`);
    }
  }
  const plain = (_, v) => (typeof v === "bigint" ? Number(v) : ArrayBuffer.isView(v) ? Array.from(v) : v);
  console.log(JSON.stringify({ decoded, selfDescribing, errors: errors.slice(0, 20), samples }, plain));
}

main(process.argv[2]).catch((error) => {
  console.error(error);
  process.exit(1);
});
