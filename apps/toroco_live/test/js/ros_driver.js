// Drives rosbridge clients for toroco_ros_server_SUITE: one JSON
// command per stdin line, one JSON event per stdout line.
// The reference client (roslib 2.1.0, ESM, over ws):
//   {"cmd":"connect","url":U}                 -> open | error | close {code}
//   {"cmd":"getTopics"}                       -> topics {topics, types}
//   {"cmd":"getServices"}                     -> services {services}
//   {"cmd":"rawTypes"}                        -> raw_types {topics, types, parsed}: each
//                                                definition parsed by @foxglove/rosmsg
//   {"cmd":"getTopicType","topic":T}          -> topic_type {type}
//   {"cmd":"subscribe","topic":T,"type":Ty, "throttle_rate":Ms, "queue_length":N}
//                                             -> message {topic, msg} per message
//   {"cmd":"subscribe_raw","topic":T}         -> raw_message {topic, secs, nsecs, msg}: a cbor-raw
//                                                subscription decoded as Foxglove does
//   {"cmd":"unsubscribe","topic":T}
//   {"cmd":"publish","topic":T,"type":Ty,"msg":M}
//   {"cmd":"drive","topic":T,"type":Ty,"msg":M,"hz":H,"ms":D}
//                                             -> drove {n, last_ms}: published n times
//                                                (last_ms: Date.now() of the last)
//   {"cmd":"call","service":S,"args":A}       -> service {ok, values}
//   {"cmd":"auth","token":T}
//   {"cmd":"close"}
// Every status operation the server sends comes out as status {level, msg, id}.
// A raw WebSocket, for what a misbehaving client does:
//   {"cmd":"raw_connect","url":U,"read":false}  (read:false never reads)
//   {"cmd":"raw_text","text":S} | {"cmd":"raw_json","json":J}
//   {"cmd":"raw_bytes","n":N}                    a text message of N bytes
//   events raw_open, raw_text {msg}, raw_close {code}, raw_error
"use strict";
const path = require("path");
const { pathToFileURL } = require("url");
const { out, commands, rawSocket } = require("./driver");

const modules = process.env.NODE_PATH;

async function main() {
  const ROSLIB = await import(pathToFileURL(path.join(modules, "roslib", "dist", "RosLib.js")).href);
  const WebSocket = require(path.join(modules, "ws"));
  let ros = null;
  const topics = new Map();
  let raw = null;

  function topic(name, type, extra) {
    const key = name + " " + JSON.stringify(extra || {});
    if (!topics.has(key)) topics.set(key, new ROSLIB.Topic({ ros, name, messageType: type, ...(extra || {}) }));
    return topics.get(key);
  }

  function connect(url) {
    ros = new ROSLIB.Ros({ url });
    const handle = ros.handleMessage.bind(ros);
    ros.handleMessage = (m) => {
      if (m && m.op === "status") out({ ev: "status", level: m.level, msg: m.msg, id: m.id || null });
      handle(m);
    };
    ros.on("connection", () => out({ ev: "open" }));
    ros.on("error", (e) => out({ ev: "error", error: String(e && e.message || e) }));
    ros.on("close", (e) => out({ ev: "close", code: e && e.code }));
  }

  function rawConnect(url, read) {
    raw = rawSocket(WebSocket, url, undefined, read, (data) => {
      let msg;
      try { msg = JSON.parse(data.toString()); } catch { msg = { unparsed: data.length }; }
      out({ ev: "raw_text", msg });
    });
  }

  commands((c) => {
    switch (c.cmd) {
      case "connect": connect(c.url); break;
      case "getTopics":
        ros.getTopics((r) => out({ ev: "topics", topics: r.topics, types: r.types }),
                      (e) => out({ ev: "topics_failed", error: String(e) }));
        break;
      case "rawTypes": {
        // rosapi/topics_and_raw_types, each definition parsed as ROS 2 tooling does
        const { parse } = require(path.join(modules, "@foxglove", "rosmsg"));
        new ROSLIB.Service({ ros, name: "rosapi/topics_and_raw_types", serviceType: "" }).callService({},
          (r) => out({ ev: "raw_types", topics: r.topics, types: r.types,
                       parsed: r.typedefs_full_text.map((t) => parse(t, { ros2: true }).map((d) => ({ name: d.name || null, fields: d.definitions.length }))) }),
          (e) => out({ ev: "raw_types_failed", error: String(e) }));
        break;
      }
      case "getServices":
        ros.getServices((s) => out({ ev: "services", services: s }),
                        (e) => out({ ev: "services_failed", error: String(e) }));
        break;
      case "getTopicType":
        ros.getTopicType(c.topic, (t) => out({ ev: "topic_type", type: t }),
                         (e) => out({ ev: "topic_type_failed", error: String(e) }));
        break;
      case "subscribe": {
        const extra = {};
        for (const k of ["throttle_rate", "queue_length"]) if (k in c) extra[k] = c[k];
        topic(c.topic, c.type, extra).subscribe((msg) => out({ ev: "message", topic: c.topic, msg }));
        out({ ev: "subscribed", topic: c.topic });
        break;
      }
      case "subscribe_raw": {
        // What Foxglove's Rosbridge connection does for ROS 2: the type's
        // definition from rosapi/topics_and_raw_types, a cbor-raw
        // subscription, each message's CDR bytes read with MessageReader.
        const { parse } = require(path.join(modules, "@foxglove", "rosmsg"));
        const { MessageReader } = require(path.join(modules, "@foxglove", "rosmsg2-serialization"));
        new ROSLIB.Service({ ros, name: "rosapi/topics_and_raw_types", serviceType: "" }).callService({}, (r) => {
          const i = r.topics.indexOf(c.topic);
          const reader = new MessageReader(parse(r.typedefs_full_text[i], { ros2: true }));
          new ROSLIB.Topic({ ros, name: c.topic, messageType: r.types[i], compression: "cbor-raw" })
            .subscribe((m) => out({ ev: "raw_message", topic: c.topic, secs: m.secs, nsecs: m.nsecs,
                                    msg: reader.readMessage(m.bytes) }));
          out({ ev: "subscribed", topic: c.topic });
        }, (e) => out({ ev: "raw_types_failed", error: String(e) }));
        break;
      }
      case "unsubscribe":
        for (const [k, t] of topics) if (k.startsWith(c.topic + " ")) t.unsubscribe();
        out({ ev: "unsubscribed", topic: c.topic });
        break;
      case "publish":
        topic(c.topic, c.type).publish(c.msg);
        out({ ev: "published" });
        break;
      case "drive": {
        const t = topic(c.topic, c.type);
        const every = 1000 / c.hz;
        const start = Date.now();
        let n = 0;
        const tick = () => {
          t.publish(c.msg); n++;
          if (Date.now() - start + every <= c.ms) setTimeout(tick, every);
          else out({ ev: "drove", n, last_ms: Date.now() });
        };
        tick();
        break;
      }
      case "call": {
        const s = new ROSLIB.Service({ ros, name: c.service, serviceType: c.type || "" });
        s.callService(c.args || {}, (values) => out({ ev: "service", ok: true, values }),
                      (e) => out({ ev: "service", ok: false, values: e }));
        break;
      }
      case "auth": ros.authenticate(c.token); break;
      case "close": ros.close(); break;
      case "raw_connect": rawConnect(c.url, c.read !== false); break;
      case "raw_text": raw.send(c.text); break;
      case "raw_json": raw.send(JSON.stringify(c.json)); break;
      case "raw_bytes": raw.send(JSON.stringify({ op: "publish", topic: "/cmd_vel", msg: { pad: "x".repeat(c.n) } })); break;
      default: return false;
    }
    return true;
  });
  out({ ev: "ready" });
}

main().catch((e) => { out({ ev: "fatal", error: String(e && e.stack || e) }); process.exit(1); });
