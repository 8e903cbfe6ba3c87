// Reads a ROS 2 MCAP file as ROS 2 tooling does: @mcap/core's indexed
// reader, each schema (encoding ros2msg) parsed with @foxglove/rosmsg
// (ros2), each message (encoding cdr) decoded with
// @foxglove/rosmsg2-serialization's MessageReader. One JSON line out:
// {"ok":true,"profile","channels":[{topic,encoding,schema,schemaEncoding}],
//  "statistics":N,"messages":N,"perTopic":{topic:N},
//  "decoded":{topic:[{"t":logTimeNs,"msg":{...}}]}} or {"ok":false,"error"}.
"use strict";
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const { withMcap } = require("./mcap_file");

const plain = (k, v) => typeof v === "bigint" ? Number(v) : ArrayBuffer.isView(v) ? Array.from(v) : v;

withMcap(process.argv[2], async (reader) => {
  const readers = new Map();
  for (const s of reader.schemasById.values()) {
    if (s.encoding !== "ros2msg") throw new Error(`schema ${s.name}: encoding ${s.encoding}`);
    readers.set(s.id, new MessageReader(parse(new TextDecoder().decode(s.data), { ros2: true })));
  }
  const channels = [...reader.channelsById.values()].map((c) => ({
    topic: c.topic, encoding: c.messageEncoding,
    schema: reader.schemasById.get(c.schemaId)?.name,
    schemaEncoding: reader.schemasById.get(c.schemaId)?.encoding,
  }));
  const perTopic = {}, decoded = {};
  let messages = 0;
  for await (const m of reader.readMessages()) {
    const c = reader.channelsById.get(m.channelId);
    if (c.messageEncoding !== "cdr") throw new Error(`${c.topic}: encoding ${c.messageEncoding}`);
    const msg = readers.get(c.schemaId).readMessage(m.data);
    perTopic[c.topic] = (perTopic[c.topic] ?? 0) + 1;
    (decoded[c.topic] ??= []).push({ t: m.logTime.toString(), msg });
    messages++;
  }
  return {
    profile: reader.header.profile, channels,
    statistics: Number(reader.statistics?.messageCount ?? -1), messages, perTopic, decoded,
  };
}, plain);
