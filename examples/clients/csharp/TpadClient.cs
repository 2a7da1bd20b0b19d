// A client of tpad-rt serve's WebSocket API (docs/serve.md) on System.Net.WebSockets: .NET, Mono and Unity.
//
// No package needed: the JSON is written and read by the small Json class below (Unity's JsonUtility cannot
// read messages whose fields depend on their type). The message names are the protocol's, the same as in the
// Python and JavaScript clients beside this folder.
//
//   var tpad = new TpadClient();
//   tpad.MessageReceived += message => { if ((string)message["type"] == "telemetry") ... };
//   tpad.ConnectAsync(new Uri("ws://127.0.0.1:8765/ws")).Wait();   // reads the hello, checks the protocol
//   tpad.Texture("name", "grating").Wait();
//   tpad.Finger(40.0, 30.0).Wait();                                 // x_mm, y_mm (force_n, t optional)
//   tpad.Lift().Wait();
//
// In Unity, MessageReceived runs on the receiving thread: queue what it gets and act on it in Update().

using System;
using System.Collections.Generic;
using System.Globalization;
using System.Net.WebSockets;
using System.Text;
using System.Threading;
using System.Threading.Tasks;

namespace TpadRt
{
    public sealed class TpadClient : IDisposable
    {
        public const int ProtocolVersion = 1;

        readonly ClientWebSocket socket = new ClientWebSocket();
        readonly SemaphoreSlim sending = new SemaphoreSlim(1, 1);
        readonly CancellationTokenSource closing = new CancellationTokenSource();
        Task receiving;

        /// <summary>The server's hello (protocol, device, texture, limits), once connected.</summary>
        public Dictionary<string, object> Hello { get; private set; }

        /// <summary>Every message the server sends after the hello, as parsed JSON (on the receiving thread).</summary>
        public event Action<Dictionary<string, object>> MessageReceived;

        /// <summary>Connect and read the hello; throws if the server speaks another protocol version.</summary>
        public async Task ConnectAsync(Uri url)
        {
            await socket.ConnectAsync(url, closing.Token);
            Hello = Json.Parse(await ReceiveTextAsync()) as Dictionary<string, object>;
            if (Hello == null || (string)Hello["type"] != "hello" || Convert.ToInt32(Hello["protocol"]) != ProtocolVersion)
                throw new InvalidOperationException("this client speaks protocol " + ProtocolVersion + "; the server said: " + Json.Write(Hello));
            receiving = Task.Run(ReceiveLoop);
        }

        /// <summary>The finger at (xMm, yMm) on the plate; forceN (N) and t (your clock, s) are optional.</summary>
        public Task Finger(double xMm, double yMm, double? forceN = null, double? t = null)
        {
            return Send(Sample("finger", xMm, yMm, forceN, t));
        }

        /// <summary>Several samples at once, oldest first: each {x_mm, y_mm[, force_n][, t]}.</summary>
        public Task Fingers(IList<double[]> samplesXYT)
        {
            var samples = new List<object>();
            foreach (var s in samplesXYT)
                samples.Add(Sample(null, s[0], s[1], null, s.Length > 2 ? s[2] : (double?)null));
            return Send(new Dictionary<string, object> { { "type", "fingers" }, { "samples", samples } });
        }

        public Task Lift(double? t = null)
        {
            var message = new Dictionary<string, object> { { "type", "lift" } };
            if (t.HasValue) message["t"] = t.Value;
            return Send(message);
        }

        /// <summary>Set a texture: how is "name" (a shipped one), "path" (a file the server may read) or "yaml".</summary>
        public Task Texture(string how, string value, object id = null)
        {
            return Send(Request("texture", id, how, value));
        }

        public Task Subscribe(double rateHz, object id = null)
        {
            return Send(Request("subscribe", id, "rate_hz", rateHz));
        }

        public Task Device(object id = null) { return Send(Request("device", id)); }

        public Task Stats(object id = null) { return Send(Request("stats", id)); }

        public Task Ping(object id = null) { return Send(Request("ping", id)); }

        public async Task Send(Dictionary<string, object> message)
        {
            var bytes = Encoding.UTF8.GetBytes(Json.Write(message));
            await sending.WaitAsync();
            try
            {
                await socket.SendAsync(new ArraySegment<byte>(bytes), WebSocketMessageType.Text, true, closing.Token);
            }
            finally
            {
                sending.Release();
            }
        }

        public async Task CloseAsync()
        {
            if (socket.State == WebSocketState.Open)
                await socket.CloseAsync(WebSocketCloseStatus.NormalClosure, "bye", CancellationToken.None);
            closing.Cancel();
            if (receiving != null)
                try { await receiving; } catch (Exception) { }
        }

        public void Dispose()
        {
            closing.Cancel();
            socket.Dispose();
        }

        static Dictionary<string, object> Sample(string type, double xMm, double yMm, double? forceN, double? t)
        {
            var message = new Dictionary<string, object>();
            if (type != null) message["type"] = type;
            message["x_mm"] = xMm;
            message["y_mm"] = yMm;
            if (forceN.HasValue) message["force_n"] = forceN.Value;
            if (t.HasValue) message["t"] = t.Value;
            return message;
        }

        static Dictionary<string, object> Request(string type, object id, string key = null, object value = null)
        {
            var message = new Dictionary<string, object> { { "type", type } };
            if (key != null) message[key] = value;
            if (id != null) message["id"] = id;
            return message;
        }

        async Task ReceiveLoop()
        {
            while (socket.State == WebSocketState.Open && !closing.IsCancellationRequested)
            {
                string text;
                try { text = await ReceiveTextAsync(); }
                catch (Exception) { return; }
                if (text == null) return;
                var message = Json.Parse(text) as Dictionary<string, object>;
                var handler = MessageReceived;
                if (message != null && handler != null) handler(message);
            }
        }

        async Task<string> ReceiveTextAsync()
        {
            var buffer = new byte[64 * 1024];
            var text = new StringBuilder();
            var decoder = Encoding.UTF8.GetDecoder();
            var chars = new char[buffer.Length];
            while (true)
            {
                var result = await socket.ReceiveAsync(new ArraySegment<byte>(buffer), closing.Token);
                if (result.MessageType == WebSocketMessageType.Close) return null;
                int count = decoder.GetChars(buffer, 0, result.Count, chars, 0, result.EndOfMessage);
                text.Append(chars, 0, count);
                if (result.EndOfMessage) return text.ToString();
            }
        }
    }

    /// <summary>Just enough JSON: Parse gives Dictionary&lt;string, object&gt;, List&lt;object&gt;, string,
    /// double, bool or null; Write takes the same (and ints, floats).</summary>
    public static class Json
    {
        public static object Parse(string text)
        {
            int at = 0;
            var value = ParseValue(text, ref at);
            SkipSpace(text, ref at);
            if (at != text.Length) throw new FormatException("JSON: text after the value at " + at);
            return value;
        }

        public static string Write(object value)
        {
            var text = new StringBuilder();
            WriteValue(text, value);
            return text.ToString();
        }

        static void WriteValue(StringBuilder text, object value)
        {
            if (value == null) { text.Append("null"); return; }
            if (value is string) { WriteString(text, (string)value); return; }
            if (value is bool) { text.Append((bool)value ? "true" : "false"); return; }
            if (value is double || value is float)
            {
                double number = Convert.ToDouble(value, CultureInfo.InvariantCulture);
                if (double.IsNaN(number) || double.IsInfinity(number))
                    throw new ArgumentException("JSON has no NaN or infinity: send finite numbers");
                text.Append(number.ToString("R", CultureInfo.InvariantCulture));
                return;
            }
            if (value is int || value is long) { text.Append(Convert.ToInt64(value).ToString(CultureInfo.InvariantCulture)); return; }
            var map = value as IDictionary<string, object>;
            if (map != null)
            {
                text.Append('{');
                bool first = true;
                foreach (var pair in map)
                {
                    if (!first) text.Append(',');
                    first = false;
                    WriteString(text, pair.Key);
                    text.Append(':');
                    WriteValue(text, pair.Value);
                }
                text.Append('}');
                return;
            }
            var list = value as System.Collections.IEnumerable;
            if (list != null)
            {
                text.Append('[');
                bool first = true;
                foreach (var item in list)
                {
                    if (!first) text.Append(',');
                    first = false;
                    WriteValue(text, item);
                }
                text.Append(']');
                return;
            }
            throw new ArgumentException("JSON: cannot write a " + value.GetType().Name);
        }

        static void WriteString(StringBuilder text, string value)
        {
            text.Append('"');
            foreach (char c in value)
            {
                if (c == '"' || c == '\\') text.Append('\\').Append(c);
                else if (c < ' ') text.Append("\\u").Append(((int)c).ToString("x4"));
                else text.Append(c);
            }
            text.Append('"');
        }

        static void SkipSpace(string text, ref int at)
        {
            while (at < text.Length && char.IsWhiteSpace(text[at])) at++;
        }

        static object ParseValue(string text, ref int at)
        {
            SkipSpace(text, ref at);
            if (at >= text.Length) throw new FormatException("JSON: unexpected end");
            char c = text[at];
            if (c == '{')
            {
                var map = new Dictionary<string, object>();
                at++;
                SkipSpace(text, ref at);
                if (text[at] == '}') { at++; return map; }
                while (true)
                {
                    SkipSpace(text, ref at);
                    var key = (string)ParseValue(text, ref at);
                    SkipSpace(text, ref at);
                    Expect(text, ref at, ':');
                    map[key] = ParseValue(text, ref at);
                    SkipSpace(text, ref at);
                    if (text[at] == ',') { at++; continue; }
                    Expect(text, ref at, '}');
                    return map;
                }
            }
            if (c == '[')
            {
                var list = new List<object>();
                at++;
                SkipSpace(text, ref at);
                if (text[at] == ']') { at++; return list; }
                while (true)
                {
                    list.Add(ParseValue(text, ref at));
                    SkipSpace(text, ref at);
                    if (text[at] == ',') { at++; continue; }
                    Expect(text, ref at, ']');
                    return list;
                }
            }
            if (c == '"') return ParseString(text, ref at);
            if (text.Substring(at).StartsWith("true")) { at += 4; return true; }
            if (text.Substring(at).StartsWith("false")) { at += 5; return false; }
            if (text.Substring(at).StartsWith("null")) { at += 4; return null; }
            int start = at;
            while (at < text.Length && "+-0123456789.eE".IndexOf(text[at]) >= 0) at++;
            return double.Parse(text.Substring(start, at - start), NumberStyles.Float, CultureInfo.InvariantCulture);
        }

        static string ParseString(string text, ref int at)
        {
            var value = new StringBuilder();
            at++;
            while (text[at] != '"')
            {
                char c = text[at++];
                if (c != '\\') { value.Append(c); continue; }
                char escaped = text[at++];
                switch (escaped)
                {
                    case 'n': value.Append('\n'); break;
                    case 't': value.Append('\t'); break;
                    case 'r': value.Append('\r'); break;
                    case 'b': value.Append('\b'); break;
                    case 'f': value.Append('\f'); break;
                    case 'u': value.Append((char)Convert.ToInt32(text.Substring(at, 4), 16)); at += 4; break;
                    default: value.Append(escaped); break;
                }
            }
            at++;
            return value.ToString();
        }

        static void Expect(string text, ref int at, char c)
        {
            if (at >= text.Length || text[at] != c) throw new FormatException("JSON: expected '" + c + "' at " + at);
            at++;
        }
    }
}
