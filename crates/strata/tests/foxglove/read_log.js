// Reads every message of a Strata MCAP log the way Foxglove does: the summary and chunk
// indexes with @mcap/core (zstd chunks through fzstd, lz4 chunks through lz4js), each CDR
// message with its channel's OMG IDL schema through @foxglove/omgidl-serialization, and each
// message of Foxglove's well-known schemas (the scene channels, JSON) checked against the JSON
// Schemas of @foxglove/schemas: the channel's schema must describe the same fields as
// Foxglove's, and every message must hold exactly those fields with values of their types.
// A JSON channel of Strata's own type (the layer plot) is checked against the JSON Schema it
// declares, as Foxglove reads it.
// Prints one JSON line: messages decoded per topic kind, the self-describing messages of other
// channels counted aside, every error met, samples, and the scene at the time given (seconds,
// second argument): the field and the first objects and frames at or after it.
"use strict";
const fs = require("fs");
const { McapIndexedReader } = require("@mcap/core");
const { parseIDL } = require("@foxglove/omgidl-parser");
const { MessageReader } = require("@foxglove/omgidl-serialization");
const foxgloveSchemas = require("@foxglove/schemas/jsonschema");
const { decompress } = require("fzstd");
const lz4 = require("lz4js");

// The parts of a JSON Schema that say what a message holds: types, fields, items, enum
// values, byte encodings. Descriptions and comments are left out.
function shape(schema) {
  const out = {};
  if (schema.type !== undefined) out.type = schema.type;
  if (schema.contentEncoding !== undefined) out.contentEncoding = schema.contentEncoding;
  if (schema.oneOf !== undefined) out.oneOf = schema.oneOf.map((c) => [c.title, c.const]);
  if (schema.properties !== undefined) {
    out.properties = {};
    for (const key of Object.keys(schema.properties).sort()) out.properties[key] = shape(schema.properties[key]);
  }
  if (schema.items !== undefined) out.items = shape(schema.items);
  return out;
}

// The first difference between two shapes, as a path; null when equal.
function difference(ours, theirs, path) {
  if (typeof ours !== "object" || typeof theirs !== "object" || ours === null || theirs === null) {
    return JSON.stringify(ours) === JSON.stringify(theirs) ? null : `${path}: ${JSON.stringify(ours)} != ${JSON.stringify(theirs)}`;
  }
  const keys = new Set([...Object.keys(ours), ...Object.keys(theirs)]);
  for (const key of keys) {
    if (!(key in ours)) return `${path}.${key}: missing in ours`;
    if (!(key in theirs)) return `${path}.${key}: not in Foxglove's`;
    const inner = difference(ours[key], theirs[key], `${path}.${key}`);
    if (inner !== null) return inner;
  }
  return null;
}

// Checks a value against a JSON Schema strictly: every declared field present, no other
// field, values of the declared types and ranges, enum values among the declared ones.
function validate(schema, value, path, errors) {
  if (errors.length > 10) return;
  if (schema.oneOf !== undefined) {
    if (!schema.oneOf.some((c) => c.const === value)) errors.push(`${path}: ${JSON.stringify(value)} is not a ${schema.title}`);
    return;
  }
  switch (schema.type) {
    case "object":
      if (typeof value !== "object" || value === null || Array.isArray(value)) return void errors.push(`${path}: not an object`);
      for (const key of Object.keys(value)) {
        if (!(key in schema.properties)) errors.push(`${path}.${key}: not a field of ${schema.title}`);
      }
      for (const [key, inner] of Object.entries(schema.properties)) {
        if (!(key in value)) errors.push(`${path}.${key}: missing`);
        else validate(inner, value[key], `${path}.${key}`, errors);
      }
      return;
    case "array":
      if (!Array.isArray(value)) return void errors.push(`${path}: not an array`);
      value.forEach((item, i) => validate(schema.items, item, `${path}[${i}]`, errors));
      return;
    case "number":
      if (typeof value !== "number" || !Number.isFinite(value)) errors.push(`${path}: not a number`);
      break;
    case "integer":
      if (!Number.isInteger(value)) errors.push(`${path}: not an integer`);
      break;
    case "string":
      if (typeof value !== "string") errors.push(`${path}: not a string`);
      break;
    case "boolean":
      if (typeof value !== "boolean") errors.push(`${path}: not a boolean`);
      break;
    default:
      errors.push(`${path}: unknown schema type ${schema.type}`);
  }
  if (schema.minimum !== undefined && value < schema.minimum) errors.push(`${path}: below ${schema.minimum}`);
  if (schema.maximum !== undefined && value > schema.maximum) errors.push(`${path}: above ${schema.maximum}`);
}

const yaw = (q) => 2 * Math.atan2(q.z, q.w);

// What the scene test compares: each entity's first cube, arrow, sphere and text.
function entities(update) {
  const out = {};
  for (const e of update.entities) {
    const at = (p) => (p === undefined ? null : { x: p.pose.position.x, y: p.pose.position.y, yaw: yaw(p.pose.orientation) });
    out[e.id] = {
      frame: e.frame_id,
      cube: at(e.cubes[0]),
      arrow: at(e.arrows[0]),
      sphere: at(e.spheres[0]),
      text: e.texts.length > 0 ? e.texts[0].text : null,
      lines: e.lines.map((l) => l.points.length),
      cylinders: e.cylinders.length,
    };
  }
  return out;
}

async function main(path, sceneAt) {
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
  const compressions = {};
  const reader = await McapIndexedReader.Initialize({
    readable,
    decompressHandlers: {
      zstd: (data, size) => {
        compressions.zstd = (compressions.zstd || 0) + 1;
        return decompress(data, new Uint8Array(Number(size)));
      },
      lz4: (data, size) => {
        compressions.lz4 = (compressions.lz4 || 0) + 1;
        const out = lz4.decompress(data, Number(size));
        if (out.length !== Number(size)) throw new Error(`lz4 chunk of ${out.length} bytes, ${size} expected`);
        return Uint8Array.from(out);
      },
    },
  });
  const readers = new Map();
  const jsonSchemas = new Map();
  const decoded = {};
  const selfDescribing = {};
  const errors = [];
  const samples = {};
  const schemaNames = {};
  const sceneAtNs = BigInt(Math.round(sceneAt * 1e9));
  const scene = { field: null, objects: null, transforms: null, plot: null, events: [] };
  for await (const message of reader.readMessages()) {
    const channel = reader.channelsById.get(message.channelId);
    const kind = channel.topic.replace(/^(home|away|t\d+)\/\d+\//, "");
    const schema = reader.schemasById.get(channel.schemaId);
    const jsonSchema = schema !== undefined && schema.encoding === "jsonschema";
    if (channel.messageEncoding === "json" && jsonSchema && !schema.name.startsWith("foxglove.")) {
      let declared = jsonSchemas.get(channel.schemaId);
      if (declared === undefined) {
        try {
          declared = JSON.parse(new TextDecoder().decode(schema.data));
        } catch (error) {
          declared = new Error(`schema: ${error.message}`);
        }
        jsonSchemas.set(channel.schemaId, declared);
      }
      schemaNames[kind] = schema.name;
      if (declared instanceof Error) {
        errors.push(`${channel.topic}: ${declared.message}`);
        continue;
      }
      let value;
      try {
        value = JSON.parse(new TextDecoder().decode(message.data));
      } catch (error) {
        errors.push(`${channel.topic} #${message.sequence}: ${error.message}`);
        continue;
      }
      const found = [];
      validate(declared, value, channel.topic, found);
      if (found.length > 0) {
        errors.push(...found);
        continue;
      }
      decoded[kind] = (decoded[kind] || 0) + 1;
      if (kind === "plot/layers" && message.logTime >= sceneAtNs && scene.plot === null) {
        scene.plot = { logTime: Number(message.logTime), robots: value.robots };
      }
      continue;
    }
    if (channel.messageEncoding === "json" && schema !== undefined && schema.name.startsWith("foxglove.")) {
      let theirs = jsonSchemas.get(channel.schemaId);
      if (theirs === undefined) {
        theirs = foxgloveSchemas[schema.name.slice("foxglove.".length)];
        if (theirs === undefined) {
          theirs = new Error(`${schema.name} is not one of Foxglove's schemas`);
        } else {
          const ours = JSON.parse(new TextDecoder().decode(schema.data));
          const differs = difference(shape(ours), shape(theirs), schema.name);
          if (differs !== null) theirs = new Error(`the schema differs from Foxglove's: ${differs}`);
        }
        jsonSchemas.set(channel.schemaId, theirs);
      }
      schemaNames[kind] = schema.name;
      if (theirs instanceof Error) {
        errors.push(`${channel.topic}: ${theirs.message}`);
        continue;
      }
      let value;
      try {
        value = JSON.parse(new TextDecoder().decode(message.data));
      } catch (error) {
        errors.push(`${channel.topic} #${message.sequence}: ${error.message}`);
        continue;
      }
      const found = [];
      validate(theirs, value, channel.topic, found);
      if (found.length > 0) {
        errors.push(...found);
        continue;
      }
      decoded[kind] = (decoded[kind] || 0) + 1;
      const at = message.logTime >= sceneAtNs;
      if (kind === "scene/field" && scene.field === null) scene.field = entities(value);
      if (kind === "scene/objects" && at && scene.objects === null) {
        scene.objects = { logTime: Number(message.logTime), entities: entities(value) };
      }
      if (kind === "scene/tf" && at && scene.transforms === null) {
        scene.transforms = {
          logTime: Number(message.logTime),
          transforms: value.transforms.map((t) => ({
            parent: t.parent_frame_id,
            child: t.child_frame_id,
            x: t.translation.x,
            y: t.translation.y,
            yaw: yaw(t.rotation),
          })),
        };
      }
      if (kind === "scene/events") scene.events.push(value.message);
      continue;
    }
    if (channel.messageEncoding !== "cdr") {
      selfDescribing[kind] = (selfDescribing[kind] || 0) + 1;
      continue;
    }
    let messageReader = readers.get(channel.schemaId);
    if (messageReader === undefined) {
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
  console.log(
    JSON.stringify(
      { decoded, selfDescribing, errors: errors.slice(0, 20), samples, schemaNames, compressions, scene },
      plain,
    ),
  );
}

main(process.argv[2], Number(process.argv[3] || 0)).catch((error) => {
  console.error(error);
  process.exit(1);
});
