// A tpad-rt serve client in C#: set a texture, swipe a finger, watch it (what python_client.py does).
//
//   tpad-rt serve                                           # in another terminal (any output)
//   mcs -out:tpad_client.exe Program.cs TpadClient.cs && mono tpad_client.exe [ws://127.0.0.1:8765/ws] [texture]
//   (or: dotnet new console, copy both files in, dotnet run -- [url] [texture])

using System;
using System.Collections.Generic;
using System.Diagnostics;
using System.Globalization;
using System.Threading;

namespace TpadRt
{
    static class Program
    {
        const double SpeedMmS = 100.0;
        const double SamplePeriodS = 0.005;
        const int Batch = 4;

        static int Main(string[] args)
        {
            var url = args.Length > 0 ? args[0] : "ws://127.0.0.1:8765/ws";
            var textureName = args.Length > 1 ? args[1] : "grating";
            try
            {
                return Run(new Uri(url), textureName);
            }
            catch (Exception error)
            {
                var inner = error is AggregateException ? error.InnerException : error;
                Console.Error.WriteLine(url + ": " + inner.Message + " (is tpad-rt serve running?)");
                return 1;
            }
        }

        static string F(object value, string format)
        {
            return Convert.ToDouble(value, CultureInfo.InvariantCulture).ToString(format, CultureInfo.InvariantCulture);
        }

        // A figure in ms to 0.01 ms, or "n/a" for none (the server sends null where nothing was measured).
        static string Milliseconds(object value)
        {
            return value == null ? "n/a" : F(value, "F2") + " ms";
        }

        static int Run(Uri url, string textureName)
        {
            var clock = Stopwatch.StartNew();
            int errors = 0;
            var textureSet = new ManualResetEventSlim();
            var statsReply = new ManualResetEventSlim();
            Dictionary<string, object> stats = null;
            using (var tpad = new TpadClient())
            {
                tpad.MessageReceived += message =>
                {
                    var type = (string)message["type"];
                    if (type == "telemetry" && (bool)message["touching"])
                        Console.WriteLine("  x " + F(message["x_mm"], "F1").PadLeft(6) + " mm  target " + F(message["target_mu"], "F3")
                                          + "  achieved " + F(message["achieved_mu"], "F3") + "  drive " + F(message["voltage_peak_v"], "F1").PadLeft(5)
                                          + " V  power " + F(message["power_peak_w"], "F3") + " W");
                    else if (type == "error")
                    {
                        Interlocked.Increment(ref errors);
                        Console.WriteLine("  error " + message["code"] + ": " + message["message"]);
                        if (message.ContainsKey("id") && (string)message["id"] == "texture") textureSet.Set();
                    }
                    else if (type == "texture" && message.ContainsKey("id") && (string)message["id"] == "texture")
                    {
                        Console.WriteLine("texture set: " + message["description"]);
                        textureSet.Set();
                    }
                    else if (type == "stats")
                    {
                        stats = (Dictionary<string, object>)message["renderer"];
                        statsReply.Set();
                    }
                };
                tpad.ConnectAsync(url).Wait();
                var device = (Dictionary<string, object>)tpad.Hello["device"];
                var plate = (Dictionary<string, object>)device["plate"];
                double lengthMm = Convert.ToDouble(plate["length_mm"]), widthMm = Convert.ToDouble(plate["width_mm"]);
                Console.WriteLine(tpad.Hello["server"] + ": " + device["label"] + ", plate " + F(lengthMm, "G") + " x " + F(widthMm, "G")
                                  + " mm, at most " + F(device["max_voltage_v"], "G") + " V; texture now: "
                                  + ((Dictionary<string, object>)tpad.Hello["texture"])["description"]);

                tpad.Texture("name", textureName, "texture").Wait();
                if (!textureSet.Wait(10000)) throw new TimeoutException("no reply to the texture within 10 s");
                if (errors > 0) return 1;
                tpad.Subscribe(20).Wait();

                // From x = 20 mm to 85 % of the plate and back at 100 mm/s, a sample every 5 ms, sent four at a time.
                var to = 0.85 * lengthMm;
                int steps = (int)((to - 20.0) / SpeedMmS / SamplePeriodS);
                var positions = new List<double>();
                for (int i = 0; i <= steps; i++) positions.Add(20.0 + (to - 20.0) * i / steps);
                for (int i = steps; i >= 0; i--) positions.Add(20.0 + (to - 20.0) * i / steps);
                double start = clock.Elapsed.TotalSeconds;
                for (int first = 0; first < positions.Count; first += Batch)
                {
                    double due = start + (first + Batch - 1) * SamplePeriodS;
                    int waitMs = (int)((due - clock.Elapsed.TotalSeconds) * 1000);
                    if (waitMs > 0) Thread.Sleep(waitMs);
                    var batch = new List<double[]>();
                    for (int i = first; i < Math.Min(first + Batch, positions.Count); i++)
                        batch.Add(new[] { positions[i], widthMm / 2, start + i * SamplePeriodS });
                    tpad.Fingers(batch).Wait();
                }
                tpad.Lift(clock.Elapsed.TotalSeconds).Wait();
                Thread.Sleep(200);
                tpad.Stats("stats").Wait();
                if (!statsReply.Wait(10000)) throw new TimeoutException("no stats within 10 s");
                Console.WriteLine("push-to-output latency p50 " + Milliseconds(stats["latency_ms_p50"]) + ", p99 "
                                  + Milliseconds(stats["latency_ms_p99"]) + "; " + errors + " errors");
                tpad.CloseAsync().Wait();
            }
            return errors > 0 ? 1 : 0;
        }
    }
}
