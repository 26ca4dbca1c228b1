// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The typed messages of tofmatd's protocol (docs/protocol.md) on top of the
// framing in wire.hpp: what the daemon builds and what the client reads back,
// with every count and string bounded on the way in. One codec, shared by the
// daemon and the client library.
#pragma once
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "tofmat/protocol/wire.hpp"

namespace tofmat::protocol {

inline constexpr std::size_t kMaxNameBytes = 64;    // material, profile, command names
inline constexpr std::size_t kMaxTextBytes = 1024;  // error messages, paths, descriptions
inline constexpr std::size_t kMaxMaterials = 255;   // label maps hold uint8 indices, 255 = none
inline constexpr std::size_t kMaxRanking = 64;      // ranking entries in a label event
inline constexpr std::uint8_t kNoLabel = 255;       // label map: no valid pixel / no decision
inline constexpr int kMaxImageSide = 4096;

// Error codes of a reply (the "code" field), stable strings clients test.
namespace codes {
inline constexpr const char* kAuth = "auth";               // TCP without the right token
inline constexpr const char* kVersion = "version";         // hello with another protocol version
inline constexpr const char* kHelloFirst = "hello_first";  // a request before hello
inline constexpr const char* kUnknownCommand = "unknown_command";
inline constexpr const char* kInvalidArgument = "invalid_argument";
inline constexpr const char* kFailed = "failed";          // a valid command that did not work (bad table file)
inline constexpr const char* kPermission = "permission";  // a control command from a client that may only read
inline constexpr const char* kFull =
    "full";  // hello: the reading slots are taken (minor 11; the rest kept for control)
}  // namespace codes

struct Hello {
  std::uint32_t protocol = kProtocolVersion;
  std::uint32_t minor = kProtocolMinor;   // (0 from a daemon that predates minor versions)
  std::string server;                     // "tofmatd 0.1.0"
  std::vector<std::string> capabilities;  // streams and commands offered
  bool auth_required = false;             // TCP: the hello request must carry the token
};
Message encode_hello(const Hello& h);
Hello decode_hello(const Message& m);

struct Request {
  std::uint32_t id = 0;
  std::string cmd;
  Json args = Json::object();
};
Message encode_request(const Request& r);
// Throws ProtocolError unless it is a request with an id, a bounded command
// name and an object of arguments.
Request decode_request(const Message& m);

struct Reply {
  std::uint32_t id = 0;
  bool ok = true;
  std::string code;   // codes:: when !ok
  std::string error;  // a sentence for people when !ok
  Json result = Json::object();
};
Message encode_reply(const Reply& r);
Reply decode_reply(const Message& m);

struct RankEntry {
  std::string material;
  double distance = 0.0;
};
// Ground truth a simulated source knows (never sent for a real camera).
struct Truth {
  std::string material;  // "" when no target
  double depth_mm = 0.0;
};
struct LabelEvent {
  std::uint64_t frame = 0;         // the source's frame sequence number
  std::uint64_t timestamp_ns = 0;  // CLOCK_MONOTONIC when the frame was complete in the daemon
  std::string profile;
  std::string state;                     // "tracking", "no_target", "final", "mixed" (sorting burst) or "unknown"
  std::string material;                  // "" when state is no_target or unknown
  std::int32_t index = -1;               // into the daemon's table materials
  double distance = 0.0;                 // Eq. (12), mm^2
  std::uint32_t valid = 0;               // elements compared
  std::uint32_t bins_covered = 0;        // depth bins observed so far
  std::vector<RankEntry> ranking;        // best first, at most kMaxRanking
  std::optional<std::uint64_t> trigger;  // sorting: the trigger this answers
  std::optional<Truth> truth;
  bool simulated = false;  // the frame came from a simulated camera (sent only when true)
  // Minor 7: the best match's calibrated probability among the candidates
  // (0..1), and its fit under the session matcher's noise model (a normal
  // deviate; absent with Eq. (12)); both absent when no_target.
  std::optional<double> confidence;
  std::optional<double> fit;
};
Message encode_label(const LabelEvent& e);
// encode(encode_label(e)) to the byte, written from the fields without a JSON
// tree: what the daemon publishes every frame (label_wire.cpp says why).
std::vector<std::uint8_t> encode_label_wire(const LabelEvent& e);
LabelEvent decode_label(const Message& m);

struct LabelMapEvent {
  std::uint64_t frame = 0, timestamp_ns = 0;
  int width = 0, height = 0;
  std::vector<std::string> materials;    // index -> name; kNoLabel = none
  std::vector<std::uint8_t> labels;      // width x height, row-major
  std::optional<double> truth_accuracy;  // simulated source: fraction of target pixels labelled right
  bool simulated = false;                // the frame came from a simulated camera (sent only when true)
};
Message encode_label_map(const LabelMapEvent& e);
LabelMapEvent decode_label_map(const Message& m);

// The depth camera's intrinsics in pixels of the whole 512 x 424 frame (pixel
// (x, y)'s centre at x + 0.5, y + 0.5) and Brown's radial (k1, k2, k3) and
// tangential (p1, p2) distortion, as the camera reports them.
struct Intrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0, k1 = 0, k2 = 0, k3 = 0, p1 = 0, p2 = 0;
};

// Depth images: "80", "16", "120" (wrapped, per frequency), "combined"
// (unwrapped) or "corrected" (minor 9: the combined depth less each labelled
// pixel's material distortion), float32 mm along each pixel's ray, NaN where
// invalid, over the region the profile decodes.
struct DepthEvent {
  std::uint64_t frame = 0, timestamp_ns = 0;
  std::string kind;
  int x0 = 0, y0 = 0, width = 0, height = 0;
  std::vector<float> depth_mm;
  // Minor 9: the camera's intrinsics (absent when the source does not know
  // them: a recording made before recordings kept them).
  std::optional<Intrinsics> intrinsics;
};
Message encode_depth(const DepthEvent& e);
DepthEvent decode_depth(const Message& m);
bool valid_depth_kind(const std::string& kind);

// The event name of an event message ("" if not an event). Throws
// ProtocolError when an event has no string "event".
std::string event_name(const Message& m);

// Field readers with bounds, for the daemon's command arguments too. Each
// throws ProtocolError naming the field.
std::string get_string(const Json& obj, const char* key, std::size_t max_bytes);
std::uint64_t get_uint(const Json& obj, const char* key, std::uint64_t max_value);
std::int64_t get_int(const Json& obj, const char* key, std::int64_t min_value, std::int64_t max_value);
double get_number(const Json& obj, const char* key);
bool get_bool(const Json& obj, const char* key);
std::vector<std::string> get_string_list(const Json& obj, const char* key, std::size_t max_items,
                                         std::size_t max_bytes);

}  // namespace tofmat::protocol
