#include "supervisor/teleopctl/session_file.hpp"

#include <fstream>
#include <sstream>

#include "common/record/session.hpp"
#include "supervisor/core/report.hpp"
#include "supervisor/core/session_output.hpp"

namespace teleop::ctl {

bool is_mcap_path(const std::string& path) {
  return path.size() >= 5 && path.compare(path.size() - 5, 5, ".mcap") == 0;
}

std::string read_text_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return in ? text.str() : std::string();
}

void SimulatedTelemetry::start(v1::Telemetry& t, bool master) const {
  t.Clear();
  t.set_session_id(master ? master_session : slave_session);
  t.set_role(master ? v1::MASTER : v1::SLAVE);
  t.set_mode(v1::ENGAGED);
  t.set_mode_reason("simulated (teleopctl simulate, lockstep)");
  t.set_device("sim");
  v1::ActiveParameters* a = t.mutable_active();
  if (p != nullptr) {
    *a->mutable_gains() = supervisor::to_proto(p->gains);
    a->set_master_fixture_stiffness_n_per_m(p->master_fixture.stiffness_N_per_m);
    a->set_slave_fixture_stiffness_n_per_m(p->slave_fixture.stiffness_N_per_m);
  }
  a->set_ramp_progress(1.0);
}
void SimulatedTelemetry::finish(v1::Telemetry& t, bool master, std::size_t cycles_so_far,
                                std::int64_t now) const {
  t.set_sent_time_ns(now);
  v1::LoopStats* l = t.mutable_loop();
  l->set_period_s(period_s);
  l->set_cycles(cycles_so_far);
  v1::LinkStats* k = t.mutable_link();
  k->set_accepted(master ? cycles_so_far : (cycles_so_far > delay ? cycles_so_far - delay : 0));
  k->set_round_trip_ns(round_trip_ns);
  k->set_round_trip_p50_ns(round_trip_ns);
  k->set_round_trip_p99_ns(round_trip_ns);
  k->set_round_trip_samples(static_cast<std::int32_t>(delay));
  k->set_one_way_latency_ns(round_trip_ns / 2);
  k->set_peer_session_id(master ? slave_session : master_session);
  k->set_peer_age_ns(master ? 0 : round_trip_ns);
}

void write_session_start(SessionFile& file, const config::LoadedConfig& cfg,
                         const v1::StabilityReport& report, std::int64_t start_ns) {
  const auto put = [&file](std::string_view topic, std::int64_t log_time_ns,
                           const google::protobuf::Message& m) {
    file.record(topic, m.GetDescriptor()->full_name(), log_time_ns, m.SerializeAsString());
  };
  put(record::topic::kConfig, start_ns, cfg.config);
  put(record::topic::kStability, start_ns, report);
  supervisor::record_session_start(file, cfg, read_text_file(cfg.source_name), report,
                                   "teleopctl simulate", start_ns);
}

void SimulatedNodes::begin(std::size_t k) {
  if (k % kCyclesPerMessage == 0) {
    frame_.start(master_, true);
    frame_.start(slave_, false);
  }
}

v1::CycleRecord& SimulatedNodes::master_cycle(std::size_t k) {
  begin(k);
  return *master_.add_cycles();
}

v1::CycleRecord& SimulatedNodes::slave_cycle() { return *slave_.add_cycles(); }

void SimulatedNodes::done(std::size_t k, bool last) {
  if ((k + 1) % kCyclesPerMessage != 0 && !last) return;
  const std::int64_t now = static_cast<std::int64_t>(k + 1) * period_ns_;
  frame_.finish(master_, true, k + 1, now);
  frame_.finish(slave_, false, k + 1, now);
  for (const bool master : {true, false}) {
    const v1::Telemetry& t = master ? master_ : slave_;
    file_.record(record::topic::telemetry(master), t.GetDescriptor()->full_name(), start_ns_ + now,
                 t.SerializeAsString());
  }
  supervisor::record_cycles(file_, true, master_, start_ns_ + now);
  supervisor::record_cycles(file_, false, slave_, start_ns_ + now);
}

}  // namespace teleop::ctl
