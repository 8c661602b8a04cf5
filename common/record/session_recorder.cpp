#include "common/record/session_recorder.hpp"

#include <google/protobuf/descriptor.h>
#include <time.h>

#include <map>
#include <mutex>
#include <stdexcept>

#include "common/record/proto_schema.hpp"
#include "common/record/recorder.hpp"

namespace teleop::record {
namespace {

class SessionRecorder final : public SessionSink {
 public:
  explicit SessionRecorder(std::filesystem::path file) : file_(std::move(file)), recorder_(file_) {}
  ~SessionRecorder() override { (void)recorder_.close(); }

  void record(std::string_view topic, const std::string& type, std::int64_t log_time_ns,
              const std::string& bytes) override {
    std::uint16_t channel = 0;
    {
      std::lock_guard lock(mutex_);
      auto it = channels_.find(std::string(topic));
      if (it == channels_.end()) {
        const google::protobuf::Descriptor* d =
            google::protobuf::DescriptorPool::generated_pool()->FindMessageTypeByName(type);
        if (d == nullptr) throw std::invalid_argument("unknown message type " + type);
        auto schema = schemas_.find(type);
        if (schema == schemas_.end()) {
          schema = schemas_.emplace(type, recorder_.add_schema(protobuf_schema(d))).first;
        }
        it = channels_
                 .emplace(std::string(topic), recorder_.add_channel(protobuf_channel(
                                                  schema->second, std::string(topic))))
                 .first;
      }
      channel = it->second;
    }
    (void)recorder_.record(channel, static_cast<std::uint64_t>(log_time_ns), bytes);
  }
  [[nodiscard]] std::string file() const override { return file_.string(); }
  [[nodiscard]] std::uint64_t recorded() const override { return recorder_.written(); }
  [[nodiscard]] std::uint64_t drops() const override { return recorder_.drops(); }
  [[nodiscard]] std::string error() const override { return recorder_.error(); }
  [[nodiscard]] std::uint64_t bytes() const override {
    std::error_code ec;
    const auto size = std::filesystem::file_size(file_, ec);
    return ec ? 0 : static_cast<std::uint64_t>(size);
  }

 private:
  std::filesystem::path file_;
  Recorder recorder_;
  std::mutex mutex_;
  std::map<std::string, std::uint16_t> channels_;
  std::map<std::string, std::uint16_t> schemas_;
};

}  // namespace

std::unique_ptr<SessionSink> make_session_recorder_at(const std::filesystem::path& file) {
  return std::make_unique<SessionRecorder>(file);
}

std::unique_ptr<SessionSink> make_session_recorder(const std::filesystem::path& dir) {
  const time_t now = time(nullptr);
  tm utc{};
  gmtime_r(&now, &utc);
  char name[64];
  strftime(name, sizeof(name), "teleop-session-%Y%m%d-%H%M%S", &utc);
  // A second file within the same second (recording stopped and started again) gets a suffix.
  std::filesystem::path file = dir / (std::string(name) + ".mcap");
  for (int i = 2; std::filesystem::exists(file); ++i) {
    file = dir / (std::string(name) + "-" + std::to_string(i) + ".mcap");
  }
  return make_session_recorder_at(file);
}

}  // namespace teleop::record
