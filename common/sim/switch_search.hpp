// The search for a mode's first switch inside one period, written once for Plant and PlantAxes
// (plant.cpp, plant_axes.cpp step_events): the period is 2^kTickBits ticks; from tick t the
// plant advances by dyadic chunks (aligned, so that each is a precomputed propagator), at most
// `guard` ticks long. A chunk whose end is past a switch (the mode no longer valid there), or
// that may hide one inside, is halved; accepted chunks grow back. A one-tick chunk that ends
// past a switch is the switch: the state continues from its far side. Where rounding disagrees
// (short chunks that lose sub-ulp motion never reach a crossing a longer chunk saw), arriving
// at the end of the nearest chunk seen past a switch takes that state.
#pragma once

#include <algorithm>
#include <cstdint>

#include "common/core/rt_safe.hpp"

namespace teleop::sim {

// g > 0 at both ends of a chunk of length dt with slopes d0, d1: if g' rises through zero
// inside (an interior minimum; g' is monotone over a guard interval), the lower bounds
// g0 + d0 t and g1 - d1 (dt - t) meet at the lowest g can reach.
TELEOP_RT [[nodiscard]] inline bool may_dip(double g0, double d0, double g1, double d1,
                                            double dt) noexcept {
  if (!(d0 < 0.0 && d1 > 0.0)) return false;
  const double t = std::clamp((g0 - g1 + d1 * dt) / (d1 - d0), 0.0, dt);
  return g0 + d0 * t <= 0.0;
}

// g > 0 at both ends and |g'| <= rate over the chunk: g >= (g0 + g1 - rate dt) / 2 inside.
// Complete where may_dip is not (g' may change sign twice: a position under a ramped force
// approaches the wall, turns, and leaves again), at the price of looking closer whenever the
// device is within a chunk's travel of the surface.
TELEOP_RT [[nodiscard]] inline bool may_reach(double g0, double g1, double rate,
                                              double dt) noexcept {
  return g0 + g1 - rate * dt <= 0.0;
}

// Where a step is in its period and what it has spent (ticks, events, propagations).
struct EventClock {
  std::uint64_t t{0};
  std::uint64_t end{0};
  int work{0};
  bool frozen{false};  // Zeno guard: past the budget, the rest of the period without search
};

// What the search asks of the plant in the current mode, State its (position, velocity):
//   advance(t, chunk, next): next = the current state propagated from tick t by chunk ticks;
//   valid(t1, s): the mode still holds in state s at tick t1;
//   may_hide(t0, t1, s1): the chunk from the current state at t0 to s1 at t1 may hide a switch;
//   accept(s): the current state becomes s;
//   on_frozen(), on_switch(): the corrections after a frozen chunk and at a switch.
template <class Advance, class Valid, class MayHide, class Accept, class OnFrozen, class OnSwitch>
struct SwitchSearchOps {
  Advance advance;
  Valid valid;
  MayHide may_hide;
  Accept accept;
  OnFrozen on_frozen;
  OnSwitch on_switch;
};
template <class... F>
SwitchSearchOps(F...) -> SwitchSearchOps<F...>;

// Advances the current state through the mode from clock.t until its first switch (true: the
// caller counts an event and classifies again), the period's end, or a frozen chunk (false).
// `next` and `past` are scratch states. RT-safe when the operations are.
template <int kMaxWork, class State, class Ops>
TELEOP_RT bool advance_to_switch(EventClock& clock, std::uint64_t guard, State& next, State& past,
                                 const Ops& ops) noexcept {
  std::uint64_t& t = clock.t;
  const std::uint64_t end = clock.end;
  std::uint64_t cap = guard;
  std::uint64_t past_t = 0;  // 0: none pending
  while (t < end) {
    std::uint64_t chunk = t == 0 ? end : (t & (~t + 1));
    chunk = std::min(chunk, cap);
    while (chunk > end - t) chunk >>= 1;
    ops.advance(t, chunk, next);
    if (++clock.work > kMaxWork) clock.frozen = true;
    if (clock.frozen) {
      ops.accept(next);
      t += chunk;
      ops.on_frozen();
      return false;  // re-classify after every frozen chunk
    }
    bool ok = ops.valid(t + chunk, next);
    if (chunk > 1 && (!ok || ops.may_hide(t, t + chunk, next))) {
      if (!ok) {
        past = next;
        past_t = t + chunk;
      }
      cap = chunk >> 1;
      continue;
    }
    if (ok && t + chunk == past_t) {
      next = past;
      ok = false;
    }
    ops.accept(next);
    t += chunk;
    if (ok) {
      cap = std::min(guard, cap << 1);
      continue;
    }
    ops.on_switch();
    return true;
  }
  return false;
}

}  // namespace teleop::sim
