// Reads an MCAP file with @mcap/core's indexed reader (the format's
// reference reader) and prints what it found as one JSON line:
// {"ok":true,"channels":[...],"schemas":[...],"statistics":N,"messages":N,"perTopic":{...},
//  "first":{topic: [first 50 messages]},"last":{topic: [last 50]}}
// or {"ok":false,"error":"..."}. Message CRCs are checked as chunks are read.
"use strict";
const { withMcap } = require("./mcap_file");

withMcap(process.argv[2], async (reader) => {
  const channels = [...reader.channelsById.values()].map((c) => ({
    id: c.id, topic: c.topic, encoding: c.messageEncoding,
    schema: reader.schemasById.get(c.schemaId)?.name,
  }));
  const schemas = [...reader.schemasById.values()].map((s) => ({
    id: s.id, name: s.name, encoding: s.encoding,
    valid: (() => { try { JSON.parse(new TextDecoder().decode(s.data)); return true; } catch { return false; } })(),
  }));
  const perTopic = {};
  let messages = 0, lastTime = 0n, ordered = true;
  const first = {}, last = {};
  for await (const m of reader.readMessages()) {
    const topic = reader.channelsById.get(m.channelId).topic;
    perTopic[topic] = (perTopic[topic] ?? 0) + 1;
    if (m.logTime < lastTime) ordered = false;
    lastTime = m.logTime;
    const body = JSON.parse(new TextDecoder().decode(m.data));
    (first[topic] ??= []).length < 50 && first[topic].push(body);
    (last[topic] ??= []).push(body);
    last[topic].length > 50 && last[topic].shift();
    messages++;
  }
  return {
    header: reader.header, channels, schemas, ordered,
    statistics: Number(reader.statistics?.messageCount ?? -1),
    chunks: reader.chunkIndexes.length, messages, perTopic, first, last,
  };
});
