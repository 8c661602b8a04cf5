#include "common/scene/resimulate.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "common/control/velocity_estimator.hpp"

namespace teleop::scene {

void SlaveOutcomeMeter::add(double slave_m, std::optional<double> master_m) {
  positions_.push_back(slave_m);
  if (master_m) {
    const double e = alpha_ * *master_m - slave_m;
    sum_sq_ += e * e;
    ++tracked_;
  }
  if (fixture_.stiffness_N_per_m > 0.0) {
    outcome_.max_penetration_m =
        std::max(outcome_.max_penetration_m, slave_m - fixture_.position_m);
  }
}

SlaveOutcome SlaveOutcomeMeter::finish(double period_s, double threshold_m) {
  SlaveOutcome& o = outcome_;
  o.cycles = positions_.size();
  o.tracking_rms_m = tracked_ > 0 ? std::sqrt(sum_sq_ / static_cast<double>(tracked_)) : 0.0;
  const double duration = static_cast<double>(positions_.size()) * period_s;
  if (positions_.size() > 4) {
    o.oscillation =
        detect_oscillation(positions_, period_s, std::min(1.0, 0.25 * duration), threshold_m);
  }
  return o;
}

double oscillation_threshold_m(const device::SimDeviceConfig& c) {
  if (!c.quantize_position) return 1e-5;
  const double count_m = 2.0 * std::numbers::pi * c.encoder.metres_per_radian /
                         (c.encoder.counts_per_rev * c.encoder.transmission_ratio);
  return std::max(1e-5, 1.5 * count_m);
}

SlaveOutcome resimulate(const ResimulationSetup& setup, const std::vector<MasterCycle>& master,
                        const std::function<void(double fraction)>& progress) {
  const control::LawParams& law = setup.law;
  const double period_s = 1.0 / setup.sample_rate_hz;
  const std::chrono::nanoseconds period{std::llround(1e9 / setup.sample_rate_hz)};
  device::SimDeviceConfig slave_cfg = setup.slave;
  slave_cfg.period = period;
  slave_cfg.initial_position_m = setup.slave0_m;

  device::SimDevice device(slave_cfg);
  for (const device::Status s : {device.configure(), device.activate()}) {
    if (!s.ok()) throw std::runtime_error("slave device: " + std::string(s.message));
  }
  control::MasterLaw master_law(law);
  control::SlaveLaw slave_law(law);
  master_law.reset(setup.master0_m);
  slave_law.reset(setup.slave0_m);
  control::VelocityEstimator slave_velocity(period_s, law.velocity_cutoff_hz);
  slave_velocity.reset(setup.slave0_m);
  const std::size_t delay = setup.round_trip_delay_samples;
  std::vector<control::PeerState> in_flight(
      delay + 1, control::PeerState{setup.master0_m, 0.0, 0.0, false, true});
  SlaveOutcomeMeter after{setup.position_scaling, setup.slave_fixture};
  bool fault = false;
  for (std::size_t k = 0; k < master.size(); ++k) {
    device::Sample ss{};
    (void)device.read(ss);
    const control::PeerState slave_state{ss.position_m, slave_velocity.step(ss.position_m),
                                         ss.force_N, false, !slave_law.faulted()};
    master_law.set_clutch(master[k].clutched);
    (void)master_law.step(master[k].position_m, slave_state);
    control::PeerState sent = master_law.peer_state();
    sent.valid = sent.valid && master[k].coupled;
    in_flight[k % (delay + 1)] = sent;
    const control::PeerState& received = in_flight[(k + 1) % (delay + 1)];
    const control::Command cs = slave_law.step(ss.position_m, ss.force_N, received);
    fault = fault || cs.flags.input_fault;
    (void)device.write(device::Command{cs.force_N});
    (void)device.advance(period);
    const bool following = received.valid && !received.clutched;
    after.add(ss.position_m, following ? std::optional<double>(received.position_m) : std::nullopt);
    if (progress && k % 1000 == 0) {
      progress(static_cast<double>(k) / static_cast<double>(master.size()));
    }
  }
  if (progress) progress(1.0);
  SlaveOutcome outcome = after.finish(period_s, oscillation_threshold_m(slave_cfg));
  outcome.fault = fault;
  return outcome;
}

}  // namespace teleop::scene
