// A client of the live Foxglove server built on Foxglove's reference implementation, @foxglove/ws-protocol's
// FoxgloveClient (the one Lichtblick uses), over the ws package, offering its one subprotocol foxglove.websocket.v1.
// Usage: node foxglove_ws_client.js URL TOPIC COUNT. It subscribes to TOPIC when advertised, prints one JSON line per
// event (open, serverInfo, advertised, subscribed, message with its bytes in base64, error, close) and closes after COUNT messages.
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const { WebSocket } = require("ws");

const [url, topic, count] = process.argv.slice(2);
const say = (event) => console.log(JSON.stringify(event));
const client = new FoxgloveClient({ ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]) });
const subscriptions = new Map();
let received = 0;

client.on("open", () => say({ event: "open" }));
client.on("serverInfo", (info) => say({ event: "serverInfo", name: info.name }));
client.on("advertise", (channels) => {
  say({ event: "advertised", topics: channels.map((c) => c.topic) });
  for (const channel of channels.filter((c) => c.topic === topic)) {
    subscriptions.set(client.subscribe(channel.id), channel);
    say({ event: "subscribed", topic: channel.topic, schemaName: channel.schemaName, encoding: channel.encoding });
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const channel = subscriptions.get(subscriptionId);
  const bytes = Buffer.from(data.buffer, data.byteOffset, data.byteLength);
  say({ event: "message", topic: channel.topic, logTimeNs: timestamp.toString(), data: bytes.toString("base64") });
  received += 1;
  if (received >= Number(count)) client.close();
});
client.on("error", (error) => say({ event: "error", message: String(error) }));
client.on("close", (event) => {
  say({ event: "close", code: event.code });
  process.exit(0);
});
