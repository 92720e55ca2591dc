// Reads a ConAg recording as a tool outside the project would: @mcap/core for the file (fzstd for
// its chunks), protobufjs for the messages, its types built from the FileDescriptorSet each
// channel's schema holds (as Lichtblick decodes protobuf channels). Prints JSON on stdout:
// {schemas: {topic: schema name}, scenes: [{tick, agents: [[id, x, y]], bricks: [[x, y]]}],
//  grid: {agent, tick, layer, cells}} (the first Grid of a brick map).
// Usage: node read_recording.mjs FILE.mcap
import { open } from "node:fs/promises";
import { McapIndexedReader } from "@mcap/core";
import { decompress } from "fzstd";
import protobuf from "protobufjs";
import descriptor from "protobufjs/ext/descriptor/index.js";

const handle = await open(process.argv[2], "r");
const size = (await handle.stat()).size;
const readable = {
  size: async () => BigInt(size),
  read: async (offset, length) => {
    const buf = Buffer.alloc(Number(length));
    await handle.read(buf, 0, Number(length), Number(offset));
    return new Uint8Array(buf.buffer, buf.byteOffset, buf.length);
  },
};
const reader = await McapIndexedReader.Initialize({
  readable,
  decompressHandlers: { zstd: (data, decompressedSize) => decompress(data, new Uint8Array(Number(decompressedSize))) },
});
let tickNs = 20000000n;
for await (const m of reader.readMetadata({ name: "conag" })) tickNs = BigInt(m.metadata.get("tick_ns"));

const types = new Map();  // channel id -> protobufjs Type
const schemas = {};
for (const [id, channel] of reader.channelsById) {
  if (channel.messageEncoding !== "protobuf") continue;
  const schema = reader.schemasById.get(channel.schemaId);
  const root = protobuf.Root.fromDescriptor(descriptor.FileDescriptorSet.decode(schema.data));
  types.set(id, root.lookupType(schema.name));
  schemas[channel.topic] = schema.name;
}
const asObject = (type, data) => type.toObject(type.decode(data), { longs: Number, bytes: Array, defaults: true });
const field = (o, snake, camel) => (o[snake] !== undefined ? o[snake] : o[camel]);

const topics = [...reader.channelsById.values()].map((c) => c.topic);
const scenes = [];
let grid = null;
for await (const msg of reader.readMessages({ topics: topics.filter((t) => t === "/world/scene" || t.endsWith("/maps/brick")) })) {
  const channel = reader.channelsById.get(msg.channelId);
  const obj = asObject(types.get(msg.channelId), msg.data);
  const tick = Number(msg.publishTime / tickNs);
  if (channel.topic === "/world/scene") {
    const scene = { tick, agents: [], bricks: [] };
    for (const e of obj.entities) {
      if (e.id.startsWith("agents/")) {
        const p = e.cylinders[0].pose.position;
        scene.agents.push([e.id.slice("agents/".length), p.x, p.y]);
      } else if (e.id === "discs/brick") {
        for (const c of e.cylinders) scene.bricks.push([c.pose.position.x, c.pose.position.y]);
      }
    }
    scenes.push(scene);
  } else if (grid === null) {
    const [, , agent, , layer] = channel.topic.split("/");
    grid = { agent, tick, layer, cells: Array.from(obj.data), columns: field(obj, "column_count", "columnCount") };
  }
}
await handle.close();
process.stdout.write(JSON.stringify({ schemas, scenes, grid }));
