// Writes a valid MCAP file that is not a toroco recording (another
// library, another topic) with @mcap/core's writer, for replay to refuse.
"use strict";
const fs = require("fs");
const { McapWriter } = require("@mcap/core");

async function main(path) {
  const chunks = [];
  let position = 0n;
  const writable = {
    position: () => position,
    write: async (buf) => { chunks.push(Buffer.from(buf)); position += BigInt(buf.byteLength); },
  };
  const writer = new McapWriter({ writable });
  await writer.start({ profile: "", library: "someone else" });
  const schemaId = await writer.registerSchema({ name: "Thing", encoding: "jsonschema",
    data: new TextEncoder().encode("{}") });
  const channelId = await writer.registerChannel({ topic: "/elsewhere", schemaId,
    messageEncoding: "json", metadata: new Map() });
  for (let i = 0; i < 10; i++) {
    await writer.addMessage({ channelId, sequence: i, logTime: BigInt(i) * 1000000n,
      publishTime: BigInt(i) * 1000000n, data: new TextEncoder().encode(JSON.stringify({ i })) });
  }
  await writer.end();
  fs.writeFileSync(path, Buffer.concat(chunks));
  console.log(JSON.stringify({ ok: true }));
}
main(process.argv[2]);
