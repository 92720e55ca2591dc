// Connects to a Foxglove WebSocket server as a client nobody in ConAg wrote: @foxglove/ws-protocol's
// FoxgloveClient over ws, offering the protocol under both its names (the SDK's server speaks it as
// foxglove.sdk.v1). Subscribes to TOPIC, decodes its first message with protobufjs from the
// advertised schema (a base64 FileDescriptorSet) and prints JSON: {schemaName, entities: [ids]}.
// Usage: node live_client.mjs ws://HOST:PORT TOPIC
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";
import protobuf from "protobufjs";
import descriptor from "protobufjs/ext/descriptor/index.js";

const { FoxgloveClient } = wsProtocol;  // a CommonJS package

const [url, topic] = process.argv.slice(2);
const timer = setTimeout(() => { console.error(`no message on ${topic} within 60 s`); process.exit(1); }, 60000);
const client = new FoxgloveClient({ ws: new WebSocket(url, ["foxglove.sdk.v1", "foxglove.websocket.v1"]) });
const subscribed = new Map();  // subscription id -> channel
client.on("error", (err) => { console.error(String(err)); process.exit(1); });
client.on("advertise", (channels) => {
  for (const channel of channels) {
    if (channel.topic === topic && subscribed.size === 0) subscribed.set(client.subscribe(channel.id), channel);
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const channel = subscribed.get(subscriptionId);
  if (!channel) return;
  const root = protobuf.Root.fromDescriptor(descriptor.FileDescriptorSet.decode(Buffer.from(channel.schema, "base64")));
  const type = root.lookupType(channel.schemaName);
  const update = type.toObject(type.decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength)));
  clearTimeout(timer);
  process.stdout.write(JSON.stringify({ schemaName: channel.schemaName, entities: update.entities.map((e) => e.id) }));
  client.close();
  process.exit(0);
});
