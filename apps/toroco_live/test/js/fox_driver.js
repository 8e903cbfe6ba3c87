// Drives Foxglove WebSocket clients for the toroco_live suites: one JSON
// command per stdin line, one JSON event per stdout line.
// The reference client (@foxglove/ws-protocol's FoxgloveClient over ws):
//   {"cmd":"connect","url":U}         -> open, serverInfo, advertise, status, ...
//   {"cmd":"subscribe","topic":T}     -> subscribed {topic, subId, channelId}
//   {"cmd":"unsubscribe","topic":T}
//   {"cmd":"subscribeGraph"}          -> graph {...}
//   {"cmd":"advertise","topic":T}     -> advertised {topic, id}
//   {"cmd":"publish","topic":T,"message":{...}}
//   {"cmd":"close"}
// A raw WebSocket, for what a misbehaving client does:
//   {"cmd":"raw_connect","url":U,"read":false}  (read:false stops reading once it has
//                                                subscribed: it reads the channels first)
//   {"cmd":"raw_text","text":S} | {"cmd":"raw_hex","hex":H}
//   {"cmd":"raw_subscribe_all"}       subscribes to every advertised channel
//   events raw_open, raw_text, raw_binary {bytes}, raw_close {code}
"use strict";
const WebSocket = require("ws");
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const { out, commands, rawSocket } = require("./driver");

let client = null;
const channels = new Map();           // topic -> channel
const subs = new Map();               // subId -> topic
const published = new Map();          // topic -> client channel id
let raw = null;
let rawChannels = [];

function connect(url) {
  client = new FoxgloveClient({ ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]) });
  client.on("open", () => out({ ev: "open" }));
  client.on("error", (e) => out({ ev: "error", error: String(e && e.message || e) }));
  client.on("close", (e) => out({ ev: "close", code: e.code }));
  client.on("serverInfo", (i) => out({ ev: "serverInfo", info: i }));
  client.on("status", (s) => out({ ev: "status", level: s.level, message: s.message }));
  client.on("advertise", (cs) => {
    for (const c of cs) channels.set(c.topic, c);
    out({ ev: "advertise", channels: cs.map((c) => ({ id: c.id, topic: c.topic, encoding: c.encoding,
      schemaName: c.schemaName, schemaEncoding: c.schemaEncoding,
      schemaValid: (() => { try { JSON.parse(c.schema); return true; } catch { return false; } })() })) });
  });
  client.on("unadvertise", (ids) => {
    const topics = [];
    for (const [t, c] of channels) if (ids.includes(c.id)) { channels.delete(t); topics.push(t); }
    out({ ev: "unadvertise", ids, topics });
  });
  client.on("connectionGraphUpdate", (g) => out({ ev: "graph", graph: g }));
  client.on("message", (m) => {
    const data = JSON.parse(new TextDecoder().decode(m.data));
    out({ ev: "message", topic: subs.get(m.subscriptionId), timestamp: String(m.timestamp), data });
  });
}

let rawReads = true;
function rawConnect(url, read) {
  rawReads = read;
  raw = rawSocket(WebSocket, url, ["foxglove.websocket.v1"], true, (data, isBinary) => {
    if (isBinary) { out({ ev: "raw_binary", bytes: data.length }); return; }
    const msg = JSON.parse(data.toString());
    if (msg.op === "advertise") rawChannels.push(...msg.channels);
    out({ ev: "raw_text", msg: msg.op === "advertise" ? { op: "advertise", count: msg.channels.length } : msg });
  });
}

commands((c) => {
  switch (c.cmd) {
    case "connect": connect(c.url); break;
    case "subscribe": {
      const ch = channels.get(c.topic);
      if (!ch) { out({ ev: "no_channel", topic: c.topic }); break; }
      const id = client.subscribe(ch.id);
      subs.set(id, c.topic);
      out({ ev: "subscribed", topic: c.topic, subId: id, channelId: ch.id });
      break;
    }
    case "unsubscribe":
      for (const [id, t] of subs) if (t === c.topic) { client.unsubscribe(id); subs.delete(id); }
      out({ ev: "unsubscribed", topic: c.topic });
      break;
    case "subscribeGraph": client.subscribeConnectionGraph(); break;
    case "advertise": {
      const id = client.advertise({ topic: c.topic, encoding: "json", schemaName: "toroco.Publish" });
      published.set(c.topic, id);
      out({ ev: "advertised", topic: c.topic, id });
      break;
    }
    case "publish":
      client.sendMessage(published.get(c.topic), new TextEncoder().encode(JSON.stringify(c.message)));
      out({ ev: "published", topic: c.topic });
      break;
    case "close": client.close(); break;
    case "raw_connect": rawConnect(c.url, c.read !== false); break;
    case "raw_text": raw.send(c.text); break;
    case "raw_hex": raw.send(Buffer.from(c.hex, "hex"), { binary: true }); break;
    case "raw_subscribe_all":
      raw.send(JSON.stringify({ op: "subscribe",
        subscriptions: rawChannels.map((ch, i) => ({ id: i, channelId: ch.id })) }));
      if (!rawReads) raw._socket.pause();
      out({ ev: "raw_subscribed", count: rawChannels.length });
      break;
    case "exit": process.exit(0);
    default: return false;
  }
  return true;
});
