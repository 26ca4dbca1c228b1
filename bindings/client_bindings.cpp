// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The C++ tofmatd client (firmware/protocol/client.hpp) for Python: the
// connection, handshake, framing and bounds live in C++; tofmat/client.py
// turns its messages into numpy arrays and dataclasses. Blocking calls
// release the GIL.
#include <pybind11/stl.h>

#include "bindings.hpp"
#include "tofmat/protocol/client.hpp"
#include "tofmat/protocol/schema.hpp"

namespace tofmat::py {
namespace {

using protocol::ClientError;
using protocol::ClientErrorKind;

// Exception classes, created once: every one is a tofmat.ClientError and also
// the built-in exception a Python programmer would catch for it.
struct ClientExceptions {
  pyb::object base, refused, timeout, version, auth, protocol, closed, command, not_permitted;
};
ClientExceptions& exceptions() {
  static ClientExceptions* e = new ClientExceptions();  // lives as long as the interpreter
  return *e;
}

pyb::object make_class(pyb::module_& m, const char* name, const pyb::tuple& bases, const char* doc) {
  pyb::dict ns;
  ns["__doc__"] = doc;
  ns["__module__"] = "tofmat";
  pyb::object cls = pyb::module_::import("builtins").attr("type")(name, bases, ns);
  m.attr(name) = cls;
  return cls;
}

[[noreturn]] void raise(const ClientError& err) {
  auto& e = exceptions();
  pyb::object cls;
  switch (err.kind()) {
    case ClientErrorKind::kRefused: cls = e.refused; break;
    case ClientErrorKind::kTimeout: cls = e.timeout; break;
    case ClientErrorKind::kVersion: cls = e.version; break;
    case ClientErrorKind::kAuth: cls = e.auth; break;
    case ClientErrorKind::kProtocol: cls = e.protocol; break;
    case ClientErrorKind::kClosed: cls = e.closed; break;
    case ClientErrorKind::kCommand:
      cls = err.code() == protocol::codes::kPermission ? e.not_permitted : e.command;
      break;
  }
  // (never a UnicodeDecodeError in place of the error: bytes that are not UTF-8 come out as \xNN)
  const std::string what = err.what();
  pyb::object message = pyb::reinterpret_steal<pyb::object>(
      PyUnicode_DecodeUTF8(what.data(), static_cast<Py_ssize_t>(what.size()), "backslashreplace"));
  if (!message) throw pyb::error_already_set();
  pyb::object exc = cls(message);
  exc.attr("code") = err.code();
  exc.attr("kind") = protocol::client_error_kind_name(err.kind());
  PyErr_SetObject(cls.ptr(), exc.ptr());
  throw pyb::error_already_set();
}

template <typename F>
auto guarded(F&& f) -> decltype(f()) {
  try {
    pyb::gil_scoped_release release;
    return f();
  } catch (const ClientError& err) {
    raise(err);
  }
}

// A JSON value as the Python object json.loads would make of it, built directly (no text between).
pyb::object to_python(const protocol::Json& j) {
  switch (j.type()) {
    case protocol::Json::value_t::object: {
      pyb::dict d;
      for (const auto& [key, value] : j.items()) d[pyb::str(key)] = to_python(value);
      return std::move(d);
    }
    case protocol::Json::value_t::array: {
      pyb::list l;
      for (const auto& value : j) l.append(to_python(value));
      return std::move(l);
    }
    case protocol::Json::value_t::string: return pyb::str(j.get_ref<const std::string&>());
    case protocol::Json::value_t::boolean: return pyb::bool_(j.get<bool>());
    case protocol::Json::value_t::number_integer: return pyb::int_(j.get<std::int64_t>());
    case protocol::Json::value_t::number_unsigned: return pyb::int_(j.get<std::uint64_t>());
    case protocol::Json::value_t::number_float: return pyb::float_(j.get<double>());
    default: return pyb::none();
  }
}

// An event as (meta dict, blob bytes) after the schema (and, for the image events, their blob's
// decoder) checked it. An event this version does not know passes to Python, which skips it.
pyb::object event_tuple(const protocol::Message& m) {
  protocol::check_event(m, false);
  const std::string name = protocol::event_name(m);
  if (name == "label") protocol::decode_label(m);  // (its ranking's entries and the index's range)
  if (name == "label_map") protocol::decode_label_map(m);
  if (name == "depth") protocol::decode_depth(m);
  return pyb::make_tuple(to_python(m.meta), pyb::bytes(reinterpret_cast<const char*>(m.blob.data()), m.blob.size()));
}

// The schema as Python data: [{"event", "streams", "blob", "fields": [{"name", "type", "always"}]}].
pyb::list schema_for_python() {
  pyb::list out;
  for (const auto& e : protocol::event_schema()) {
    pyb::list streams, fields;
    for (const auto s : e.streams) streams.append(pyb::str(std::string(s)));
    for (const auto& f : e.fields) {
      pyb::dict d;
      d["name"] = std::string(f.name);
      d["type"] = protocol::field_type_name(f.type);
      d["always"] = f.always;
      fields.append(d);
    }
    pyb::dict d;
    d["event"] = std::string(e.event);
    d["streams"] = streams;
    d["blob"] = e.blob;
    d["fields"] = fields;
    out.append(d);
  }
  return out;
}

class PyConnection {
 public:
  PyConnection(const std::string& address, const std::string& token, double timeout_s) {
    protocol::ClientOptions o;
    o.token = token;
    o.timeout_ms = static_cast<int>(timeout_s * 1000.0);
    client_ = guarded([&] { return std::make_unique<protocol::Client>(address, o); });
  }
  pyb::object request(const std::string& cmd, const std::string& args_json) {
    protocol::Json args;
    try {
      args = protocol::Json::parse(args_json);
    } catch (const protocol::Json::exception& e) {
      throw pyb::value_error(std::string("command arguments are not JSON: ") + e.what());
    }
    const auto result = guarded([&] { return client_->request(cmd, args); });
    return to_python(result);
  }
  pyb::object next_event(double timeout_s) {
    const int ms = timeout_s < 0 ? -1 : static_cast<int>(timeout_s * 1000.0);
    std::optional<protocol::Message> m = guarded([&] { return client_->next_event(ms); });
    if (!m) return pyb::none();
    try {
      return event_tuple(*m);
    } catch (const protocol::ProtocolError& e) {
      client_->close();
      raise(ClientError(ClientErrorKind::kProtocol, std::string("malformed event from tofmatd: ") + e.what()));
    }
  }
  pyb::dict hello() const {
    pyb::dict d;
    d["protocol"] = client_->hello().protocol;
    d["minor"] = client_->hello().minor;
    d["server"] = client_->hello().server;
    d["capabilities"] = client_->hello().capabilities;
    d["auth_required"] = client_->hello().auth_required;
    d["role"] = client_->role();
    return d;
  }
  bool connected() const { return client_ && client_->connected(); }
  std::size_t pending_events() const { return client_->pending_events(); }
  std::size_t pending_bytes() const { return client_->pending_bytes(); }
  std::uint64_t dropped_events() const { return client_->dropped_events(); }
  void close() {
    if (client_) client_->close();
  }

 private:
  std::unique_ptr<protocol::Client> client_;
};

}  // namespace

void register_client(pyb::module_& m) {
  auto& e = exceptions();
  pyb::module_ builtins = pyb::module_::import("builtins");
  e.base = make_class(m, "ClientError", pyb::make_tuple(builtins.attr("Exception")),
                      "Base of every error talking to tofmatd (attributes: kind, code).");
  e.refused = make_class(m, "DaemonUnavailableError", pyb::make_tuple(e.base, builtins.attr("ConnectionRefusedError")),
                         "Nothing listens at the address: tofmatd is not running, or the path/port is wrong.");
  e.timeout = make_class(m, "DaemonTimeoutError", pyb::make_tuple(e.base, builtins.attr("TimeoutError")),
                         "tofmatd did not answer in time.");
  e.version = make_class(m, "ProtocolVersionError", pyb::make_tuple(e.base),
                         "tofmatd speaks another protocol version than this SDK.");
  e.auth = make_class(m, "AuthenticationError", pyb::make_tuple(e.base, builtins.attr("PermissionError")),
                      "tofmatd refused the token (TCP connections need the daemon's shared secret).");
  e.protocol =
      make_class(m, "ProtocolError", pyb::make_tuple(e.base), "tofmatd sent something the protocol does not allow.");
  e.closed = make_class(m, "ConnectionClosedError", pyb::make_tuple(e.base, builtins.attr("ConnectionError")),
                        "The connection to tofmatd went away (it stopped or restarted).");
  e.command =
      make_class(m, "CommandError", pyb::make_tuple(e.base),
                 "tofmatd refused a command (attribute code: invalid_argument, unknown_command, failed, permission).");
  e.not_permitted = make_class(m, "NotPermittedError", pyb::make_tuple(e.command, builtins.attr("PermissionError")),
                               "The command needs the control role and this connection may only read (code "
                               "permission): on the Unix socket control is the daemon's user or its control group, "
                               "on TCP the control token.");

  pyb::class_<PyConnection>(m, "ClientConnection", "A connection to tofmatd (use tofmat.Client).")
      .def(pyb::init<const std::string&, const std::string&, double>(), pyb::arg("address"), pyb::arg("token") = "",
           pyb::arg("timeout") = 5.0)
      .def("request", &PyConnection::request, pyb::arg("cmd"), pyb::arg("args_json") = "{}")
      .def("next_event", &PyConnection::next_event, pyb::arg("timeout"))
      .def_property_readonly("hello", &PyConnection::hello)
      .def_property_readonly("connected", &PyConnection::connected)
      .def_property_readonly("pending_events", &PyConnection::pending_events)
      .def_property_readonly("pending_bytes", &PyConnection::pending_bytes)
      .def_property_readonly("dropped_events", &PyConnection::dropped_events)
      .def("close", &PyConnection::close);
  m.attr("PROTOCOL_VERSION") = protocol::kProtocolVersion;
  m.attr("PROTOCOL_MINOR") = protocol::kProtocolMinor;
  m.def("protocol_schema", &schema_for_python,
        "The protocol's events (firmware/protocol/schema.hpp): each one's name, streams, blob and fields.");
}

}  // namespace tofmat::py
