// Decode navreplay's estimates MCAP with Foxglove's own decoders (@mcap/core,
// @foxglove/rosmsg, @foxglove/rosmsg2-serialization): every message of every topic, its
// header stamp against the MCAP log time. Prints a JSON summary; exits 1 on any problem.
//
//   cd tests/foxglove && npm ci && node check_exports.mjs OUT/estimates.mcap
import { open } from "node:fs/promises";
import { McapIndexedReader } from "@mcap/core";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import { decompress as zstd } from "fzstd";
import lz4 from "lz4js";

const path = process.argv[2];
if (!path) {
  console.error("usage: node check_exports.mjs ESTIMATES.mcap");
  process.exit(2);
}
const handle = await open(path, "r");
const size = (await handle.stat()).size;
const readable = {
  size: async () => BigInt(size),
  read: async (offset, length) => {
    const buf = new Uint8Array(Number(length));
    await handle.read(buf, 0, Number(length), Number(offset));
    return buf;
  },
};
const reader = await McapIndexedReader.Initialize({
  readable,
  decompressHandlers: {
    zstd: (data, decompressedSize) => zstd(data, new Uint8Array(Number(decompressedSize))),
    lz4: (data, decompressedSize) => lz4.decompress(data, Number(decompressedSize)),
  },
});
const readers = new Map();
for (const [id, channel] of reader.channelsById) {
  const schema = reader.schemasById.get(channel.schemaId);
  const text = new TextDecoder().decode(schema.data);
  readers.set(id, { topic: channel.topic, type: schema.name,
                    reader: new MessageReader(parse(text, { ros2: true })) });
}
const topics = {};
const problems = [];
const frames = new Set();
for await (const message of reader.readMessages()) {
  const { topic, type, reader: r } = readers.get(message.channelId);
  const msg = r.readMessage(message.data);
  const header = type === "tf2_msgs/msg/TFMessage" ? msg.transforms[0].header : msg.header;
  const stamp = BigInt(header.stamp.sec) * 1000000000n + BigInt(header.stamp.nanosec);
  if (stamp !== message.logTime) problems.push(`${topic}: stamp ${stamp} != log time ${message.logTime}`);
  if (type === "tf2_msgs/msg/TFMessage") frames.add(`${header.frame_id}->${msg.transforms[0].child_frame_id}`);
  if (type === "sensor_msgs/msg/NavSatFix" && !(Math.abs(msg.latitude) <= 90)) problems.push(`${topic}: latitude ${msg.latitude}`);
  topics[topic] = topics[topic] ?? { type, messages: 0 };
  topics[topic].messages += 1;
}
await handle.close();
const total = Object.values(topics).reduce((n, t) => n + t.messages, 0);
console.log(JSON.stringify({ file: path, messages: total, topics, tf: [...frames].sort(),
                             problems: problems.slice(0, 10) }, null, 2));
process.exit(problems.length ? 1 : 0);
