// The session file `teleopctl simulate --out FILE.mcap` writes (docs/simulate.md "Session
// files"): a SessionSink over a synchronous McapWriter, and the two simulated nodes' Telemetry
// messages, as a live session records them (common/record/session.hpp), for one axis
// (simulate_command.cpp) and for several (simulate_session_axes.cpp).
#pragma once

#include <google/protobuf/message.h>

#include <cstddef>
#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <string_view>

#include "common/config/config_loader.hpp"
#include "common/core/teleop_params.hpp"
#include "common/record/mcap_writer.hpp"
#include "common/record/proto_schema.hpp"
#include "common/record/session_recorder.hpp"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::ctl {

// Cycles per Telemetry message: a live node's 50 messages/s at 1 kHz.
inline constexpr std::size_t kCyclesPerMessage = 20;

[[nodiscard]] bool is_mcap_path(const std::string& path);

// The file as read ("" when it cannot be read: the loaded configuration is attached then).
[[nodiscard]] std::string read_text_file(const std::string& path);

// The session file: a SessionSink over a synchronous McapWriter, one schema per type.
class SessionFile final : public record::SessionSink {
 public:
  explicit SessionFile(const std::string& path) : path_(path), writer_(path, writer_options()) {}
  void record(std::string_view topic, const std::string& type, std::int64_t log_time_ns,
              const std::string& bytes) override {
    record_published(topic, type, log_time_ns, log_time_ns, bytes);
  }
  void record_published(std::string_view topic, const std::string& type, std::int64_t log_time_ns,
                        std::int64_t publish_time_ns, const std::string& bytes) override {
    check(writer_.write(channel(type, topic), static_cast<std::uint64_t>(log_time_ns),
                        static_cast<std::uint64_t>(publish_time_ns), bytes));
  }
  void metadata(std::string_view name, const std::map<std::string, std::string>& values) override {
    check(writer_.write_metadata(std::string(name), values));
  }
  void attachment(std::string_view name, std::string_view media_type, std::int64_t log_time_ns,
                  const std::string& data) override {
    record::AttachmentDef a;
    a.log_time_ns = static_cast<std::uint64_t>(log_time_ns);
    a.create_time_ns = a.log_time_ns;
    a.name = std::string(name);
    a.media_type = std::string(media_type);
    a.data = data;
    check(writer_.write_attachment(a));
  }
  [[nodiscard]] std::string file() const override { return path_; }
  void close() { check(writer_.close()); }

 private:
  void check(bool ok) const {
    if (!ok) throw std::runtime_error(writer_.error());
  }
  [[nodiscard]] static record::WriterOptions writer_options() {
    record::WriterOptions options;
    options.library = record::session_library();
    // Offline: chunks by size only, so the same scene and start give the same bytes.
    options.max_chunk_age = std::chrono::nanoseconds::max();
    return options;
  }
  std::uint16_t channel(const std::string& type, std::string_view topic) {
    const auto known = channels_.find(std::string(topic));
    if (known != channels_.end()) return known->second;
    const google::protobuf::Descriptor* d =
        google::protobuf::DescriptorPool::generated_pool()->FindMessageTypeByName(type);
    if (d == nullptr) throw std::invalid_argument("unknown message type " + type);
    auto it = schemas_.find(d);
    if (it == schemas_.end()) {
      it = schemas_.emplace(d, writer_.add_schema(record::protobuf_schema(d))).first;
    }
    const std::uint16_t id =
        writer_.add_channel(record::protobuf_channel(it->second, std::string(topic)));
    channels_.emplace(std::string(topic), id);
    return id;
  }

  std::string path_;
  record::McapWriter writer_;
  std::map<const google::protobuf::Descriptor*, std::uint16_t> schemas_{};
  std::map<std::string, std::uint16_t> channels_{};
};

// What both nodes' Telemetry messages carry besides their cycles: identity, the law in force
// (one axis: `p`'s gains and fixtures; several axes, p null: the parameters built with, as a
// live n-axis node publishes them), loop and link statistics of a lockstep run.
struct SimulatedTelemetry {
  const TeleopParams* p{nullptr};
  std::uint64_t master_session{0};
  std::uint64_t slave_session{0};
  double period_s{0.0};
  std::size_t delay{0};
  std::int64_t round_trip_ns{0};

  void start(v1::Telemetry& t, bool master) const;
  void finish(v1::Telemetry& t, bool master, std::size_t cycles_so_far, std::int64_t now) const;
};

// The start of a session: /config, /supervisor/stability, the metadata and the configuration
// attachment at `start_ns`.
void write_session_start(SessionFile& file, const config::LoadedConfig& cfg,
                         const v1::StabilityReport& report, std::int64_t start_ns);

// Both nodes' cycles in Telemetry messages of kCyclesPerMessage cycles, each logged at the end
// of its last cycle's period (start_ns plus simulated time), and every cycle on /master/cycle
// and /slave/cycle (supervisor/core/session_output.hpp).
class SimulatedNodes {
 public:
  SimulatedNodes(SessionFile& file, const SimulatedTelemetry& frame, std::int64_t start_ns,
                 std::int64_t period_ns)
      : file_(file), frame_(frame), start_ns_(start_ns), period_ns_(period_ns) {}
  // The records of cycle k (from 0) of the master, then of the slave, to fill.
  [[nodiscard]] v1::CycleRecord& master_cycle(std::size_t k);
  [[nodiscard]] v1::CycleRecord& slave_cycle();
  // After cycle k: both nodes' messages out when full or when k is the last cycle.
  void done(std::size_t k, bool last);

 private:
  void begin(std::size_t k);
  SessionFile& file_;
  SimulatedTelemetry frame_;
  std::int64_t start_ns_;
  std::int64_t period_ns_;
  v1::Telemetry master_{};
  v1::Telemetry slave_{};
};

}  // namespace teleop::ctl
