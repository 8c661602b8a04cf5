#include "common/record/session_recorder.hpp"

#include <google/protobuf/descriptor.h>
#include <time.h>

#include <map>
#include <mutex>
#include <stdexcept>

#include "common/core/version.hpp"
#include "common/record/proto_schema.hpp"
#include "common/record/recorder.hpp"

namespace teleop::record {
namespace {

class SessionRecorder final : public SessionSink {
 public:
  explicit SessionRecorder(std::filesystem::path file)
      : file_(std::move(file)), recorder_(file_, options()) {}
  ~SessionRecorder() override { (void)recorder_.close(); }

  void record(std::string_view topic, const std::string& type, std::int64_t log_time_ns,
              const std::string& bytes) override {
    record_published(topic, type, log_time_ns, log_time_ns, bytes);
  }
  void record_published(std::string_view topic, const std::string& type, std::int64_t log_time_ns,
                        std::int64_t publish_time_ns, const std::string& bytes) override {
    const std::uint16_t channel = channel_for(topic, type);
    (void)recorder_.record(channel, static_cast<std::uint64_t>(log_time_ns),
                           static_cast<std::uint64_t>(publish_time_ns), bytes);
  }
  void metadata(std::string_view name, const std::map<std::string, std::string>& values) override {
    recorder_.metadata(std::string(name), values);
  }
  void attachment(std::string_view name, std::string_view media_type, std::int64_t log_time_ns,
                  const std::string& data) override {
    AttachmentDef a;
    a.log_time_ns = static_cast<std::uint64_t>(log_time_ns);
    a.create_time_ns = a.log_time_ns;
    a.name = std::string(name);
    a.media_type = std::string(media_type);
    a.data = data;
    recorder_.attachment(std::move(a));
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
  // The channel of `topic` (created with its schema on first use).
  std::uint16_t channel_for(std::string_view topic, const std::string& type) {
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
    return channel;
  }

  // The MCAP header names the program and its version: "teleop 0.1.0".
  static RecorderOptions options() {
    RecorderOptions o;
    o.writer.library = session_library();
    return o;
  }

  std::filesystem::path file_;
  Recorder recorder_;
  std::mutex mutex_;
  std::map<std::string, std::uint16_t> channels_;
  std::map<std::string, std::uint16_t> schemas_;
};

}  // namespace

std::string session_library() { return "teleop " + std::string(version()); }

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
