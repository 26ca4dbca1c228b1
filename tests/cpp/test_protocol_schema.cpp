// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The protocol's event schema: every encoder follows it to the letter, and check_event refuses what breaks it.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <set>
#include <string>

#include "tofmat/protocol/messages.hpp"
#include "tofmat/protocol/schema.hpp"

using namespace tofmat::protocol;

namespace {

LabelEvent full_label() {
  LabelEvent e;
  e.frame = 7;
  e.timestamp_ns = 123;
  e.profile = "sorting";
  e.state = "final";
  e.material = "cork";
  e.index = 2;
  e.distance = 0.5;
  e.valid = 20;
  e.bins_covered = 10;
  e.ranking = {{"cork", 0.5}, {"paper", 0.9}};
  e.trigger = 3;
  e.truth = Truth{"cork", 850.0};
  e.simulated = true;
  return e;
}

Message event(const Json& meta) {
  Message m;
  m.type = MessageType::kEvent;
  m.meta = meta;
  return m;
}

}  // namespace

TEST(ProtocolSchema, EveryEncoderFollowsItToTheLetter) {
  check_event(encode_label(full_label()), true);
  LabelEvent bare;  // no optional field
  bare.profile = "handheld";
  bare.state = "no_target";
  check_event(encode_label(bare), true);
  LabelMapEvent map;
  map.width = 2;
  map.height = 1;
  map.materials = {"cork"};
  map.labels = {0, kNoLabel};
  map.truth_accuracy = 0.5;
  map.simulated = true;
  check_event(encode_label_map(map), true);
  DepthEvent depth;
  depth.kind = "combined";
  depth.width = 1;
  depth.height = 1;
  depth.depth_mm = {900.0F};
  check_event(encode_depth(depth), true);
  depth.intrinsics = Intrinsics{365, 365, 256, 212, 0, 0, 0, 0, 0};
  check_event(encode_depth(depth), true);
}

TEST(ProtocolSchema, StreamsComeFromTheEventsAndOnlyBloblessOnesArePolled) {
  const auto& s = stream_names();
  EXPECT_EQ(std::set<std::string>(s.begin(), s.end()),
            (std::set<std::string>{"labels", "label_map", "depth:80", "depth:16", "depth:120", "depth:combined",
                                   "depth:corrected", "device", "sort", "line", "reset"}));
  EXPECT_TRUE(valid_stream("depth:16"));
  EXPECT_FALSE(valid_stream("depth"));
  EXPECT_FALSE(valid_stream(""));
  EXPECT_TRUE(pollable_stream("labels"));
  EXPECT_TRUE(pollable_stream("sort"));
  EXPECT_FALSE(pollable_stream("label_map"));
  EXPECT_FALSE(pollable_stream("depth:combined"));
  EXPECT_FALSE(pollable_stream("depth:corrected"));
  EXPECT_FALSE(pollable_stream("sparkles"));
  ASSERT_NE(find_event("label"), nullptr);
  EXPECT_EQ(find_event("sparkles"), nullptr);
  for (const auto& e : event_schema()) {  // one name per field, "event" never one of them
    std::set<std::string_view> names;
    for (const auto& f : e.fields) {
      EXPECT_TRUE(names.insert(f.name).second) << e.event << "." << f.name;
      EXPECT_NE(f.name, "event");
    }
  }
}

TEST(ProtocolSchema, AMissingFieldAWrongTypeOrAnOverlongNameIsRefused) {
  const Message good = encode_label(full_label());
  Message m = good;
  m.meta.erase("distance");
  EXPECT_THROW(check_event(m, false), ProtocolError);
  m = good;
  m.meta.erase("trigger");  // optional: may be left out
  EXPECT_NO_THROW(check_event(m, true));
  m = good;
  m.meta["frame"] = -1;
  EXPECT_THROW(check_event(m, false), ProtocolError);
  m = good;
  m.meta["distance"] = "far";
  EXPECT_THROW(check_event(m, false), ProtocolError);
  m = good;
  m.meta["material"] = std::string(kMaxNameBytes + 1, 'x');
  EXPECT_THROW(check_event(m, false), ProtocolError);
  m = good;
  m.meta["simulated"] = nullptr;  // the rule for absent values: leave the field out, never null
  EXPECT_THROW(check_event(m, false), ProtocolError);
  m = good;
  m.meta["ranking"] = Json::array({1, 2});
  EXPECT_THROW(check_event(m, false), ProtocolError);
  m = good;
  m.blob = {1};
  EXPECT_THROW(check_event(m, false), ProtocolError);
  Message device = event({{"event", "device"},
                          {"state", "streaming"},
                          {"message", std::string(kMaxTextBytes + 1, 'x')},
                          {"timestamp_ns", 1}});
  EXPECT_THROW(check_event(device, false), ProtocolError);
}

TEST(ProtocolSchema, AClientTakesWhatALaterMinorAddsThePublisherDoesNot) {
  Message m = encode_label(full_label());
  m.meta["sparkle"] = 3;  // a field a later minor version adds
  EXPECT_NO_THROW(check_event(m, false));
  EXPECT_THROW(check_event(m, true), ProtocolError);
  const Message unknown = event({{"event", "sparkles"}, {"n", 1}});
  EXPECT_NO_THROW(check_event(unknown, false));
  EXPECT_THROW(check_event(unknown, true), ProtocolError);
}

TEST(ProtocolSchema, TheDaemonsOwnEventsOfTheLineAndTheButtonFollowIt) {
  // The shapes daemon.cpp and sorting_line.cpp publish (their tests publish through the server, which
  // checks every message against the schema in debug builds); here the same shapes, checked strictly.
  check_event(event({{"event", "device"}, {"state", "streaming"}, {"message", "ok"}, {"timestamp_ns", 5}}), true);
  check_event(event({{"event", "reset"}, {"by", "button"}, {"timestamp_ns", 5}}), true);
  check_event(event({{"event", "line"}, {"kind", "alarm"}, {"message", "on"}, {"alarm", true}, {"timestamp_ns", 5}}),
              true);
  check_event(event({{"event", "sort"},
                     {"state", "decided"},
                     {"item", 1},
                     {"trigger_ns", 2},
                     {"material", "cork"},
                     {"distance", 0.5},
                     {"outlet", "cork"},
                     {"reason", "sorted"},
                     {"decided_ns", 3},
                     {"margin_ms", 100.0},
                     {"fire_ns", 4},
                     {"truth", "cork"}}),
              true);
  EXPECT_THROW(check_event(event({{"event", "sort"}, {"state", "decided"}}), false), ProtocolError);
}
