// A roslib client of a rosbridge server where a robot in client mode
// advertised its topics: waits (at most 15 s) until getTopics lists the
// topic named on the command line, subscribes to it until one message
// comes, then publishes the Twist of the command line on /cmd_vel at
// 10 Hz, `count` times. One JSON line out:
// {"ok":true,"topics":[...],"types":[...],"message":{...},"published":N}
// or {"ok":false,"error":"..."}.
// usage: node roslib_peer.js URL TOPIC TWIST_JSON COUNT
"use strict";
const path = require("path");
const { pathToFileURL } = require("url");

async function main([url, topic, twistJson, count]) {
  const ROSLIB = await import(pathToFileURL(path.join(process.env.NODE_PATH, "roslib/dist/RosLib.js")).href);
  const ros = new ROSLIB.Ros({ url });
  await new Promise((ok, fail) => { ros.on("connection", ok); ros.on("error", fail); });
  const until = Date.now() + 15000;
  let listed;
  for (;;) {
    listed = await new Promise((ok, fail) => ros.getTopics(ok, fail));
    if (listed.topics.includes(topic) || Date.now() > until) break;
    await new Promise((ok) => setTimeout(ok, 100));
  }
  if (!listed.topics.includes(topic)) throw new Error(`${topic} not listed: ${listed.topics}`);
  const type = listed.types[listed.topics.indexOf(topic)];
  const sub = new ROSLIB.Topic({ ros, name: topic, messageType: type });
  const message = await new Promise((ok, fail) => {
    const t = setTimeout(() => fail(new Error(`no message on ${topic}`)), 15000);
    sub.subscribe((m) => { clearTimeout(t); ok(m); });
  });
  sub.unsubscribe();
  const cmd = new ROSLIB.Topic({ ros, name: "/cmd_vel", messageType: "geometry_msgs/msg/Twist" });
  const twist = JSON.parse(twistJson);
  let published = 0;
  for (let i = 0; i < Number(count); i++) {
    cmd.publish(twist);
    published++;
    await new Promise((ok) => setTimeout(ok, 100));
  }
  console.log(JSON.stringify({ ok: true, topics: listed.topics, types: listed.types, message, published }));
  ros.close();
}
main(process.argv.slice(2)).catch((e) => {
  console.log(JSON.stringify({ ok: false, error: String((e && e.message) || e) }));
  process.exit(0);
});
