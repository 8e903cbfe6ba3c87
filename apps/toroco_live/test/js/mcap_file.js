// Opens an MCAP file with @mcap/core's indexed reader (the format's
// reference reader) and runs `read(reader)` on it; prints what `read`
// returns as one JSON line, or {"ok":false,"error":"..."} if the file or
// `read` fails. Message CRCs are checked as chunks are read.
"use strict";
const fs = require("fs/promises");
const { McapIndexedReader } = require("@mcap/core");

async function withMcap(path, read, replacer) {
  const handle = await fs.open(path, "r");
  const readable = {
    size: async () => BigInt((await handle.stat()).size),
    read: async (offset, length) => {
      const buf = Buffer.alloc(Number(length));
      await handle.read(buf, 0, Number(length), Number(offset));
      return new Uint8Array(buf.buffer, buf.byteOffset, buf.byteLength);
    },
  };
  try {
    const reader = await McapIndexedReader.Initialize({ readable });
    console.log(JSON.stringify({ ok: true, ...(await read(reader)) }, replacer));
  } catch (e) {
    console.log(JSON.stringify({ ok: false, error: String((e && e.message) || e) }));
  } finally {
    await handle.close();
  }
}

module.exports = { withMcap };
