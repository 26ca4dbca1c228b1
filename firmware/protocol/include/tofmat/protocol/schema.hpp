// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The one definition of the protocol's events: each event's name, the streams that carry it, its
// fields with their types and whether they are always there, and whether a blob follows.
//
// The daemon checks what it publishes against it (in debug builds and the tests), the C++ and the
// Python clients check what they receive against it, the stream names everywhere come from it, and
// docs/protocol.md is tested against it. A minor version adds to it; nothing is ever removed.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "tofmat/protocol/messages.hpp"

namespace tofmat::protocol {

enum class FieldType {
  kName,    // a string of at most kMaxNameBytes (a material, a state, a reason)
  kText,    // a string for people (a device's message), at most kMaxTextBytes
  kUint,    // an integer >= 0
  kInt,     // an integer
  kNumber,  // a finite number
  kBool,
  kNames,   // a list of names
  kObject,  // an object (its keys are described in docs/protocol.md)
  kList,    // a list of objects
};

struct FieldSpec {
  std::string_view name;
  FieldType type;
  bool always;  // false: left out when it has no value (the protocol's one rule for absent values)
};

struct EventSpec {
  std::string_view event;                 // the metadata's "event"
  std::vector<std::string_view> streams;  // the streams that carry it
  bool blob;                              // a binary payload follows the metadata
  std::vector<FieldSpec> fields;          // besides "event"
};

// Every event of this version of the protocol.
const std::vector<EventSpec>& event_schema();

// Every stream a client may subscribe to, in the schema's order.
const std::vector<std::string>& stream_names();
bool valid_stream(std::string_view stream);

// The event's spec, or nullptr for an event this version does not know (a later minor's).
const EventSpec* find_event(std::string_view event);

// The streams that may be polled with the `latest` command: those whose events carry no blob.
bool pollable_stream(std::string_view stream);

const char* field_type_name(FieldType type);

// Checks an event message against its spec: every field that is always there is present and every
// present field has its type and bound. Throws ProtocolError naming the field. `strict` also
// refuses a field the spec does not name: for what this build publishes, never for what a client
// receives (a later minor version adds fields). An event this version does not know passes
// unchecked unless `strict`.
void check_event(const Message& m, bool strict);

}  // namespace tofmat::protocol
