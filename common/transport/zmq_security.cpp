#include "common/transport/zmq_security.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <charconv>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <zmq.hpp>

#include "common/transport/zap_handler.hpp"

namespace teleop::transport {

namespace {

namespace fs = std::filesystem;

constexpr std::string_view kZ85Alphabet =
    "0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ.-:+=^!/*?&<>()[]{}@%$#";
constexpr std::size_t kKeyBytes = 32;
constexpr std::string_view kPublicField = "public-key";
constexpr std::string_view kSecretField = "secret-key";

std::string errno_text(int err) { return std::strerror(err); }

std::string_view trim(std::string_view s) {
  constexpr std::string_view kSpace = " \t\r\n";
  const std::size_t first = s.find_first_not_of(kSpace);
  if (first == std::string_view::npos) return {};
  const std::size_t last = s.find_last_not_of(kSpace);
  return s.substr(first, last - first + 1);
}

// Closes a POSIX descriptor on every path out of a function.
class FileDescriptor {
 public:
  explicit FileDescriptor(int fd) : fd_(fd) {}
  ~FileDescriptor() {
    if (fd_ >= 0) ::close(fd_);
  }
  FileDescriptor(const FileDescriptor&) = delete;
  FileDescriptor& operator=(const FileDescriptor&) = delete;
  FileDescriptor(FileDescriptor&&) = delete;
  FileDescriptor& operator=(FileDescriptor&&) = delete;
  [[nodiscard]] int get() const { return fd_; }
  // Closes now, so a failing close (a write that never reached the disk) can be reported.
  [[nodiscard]] int close() {
    const int rc = ::close(fd_);
    fd_ = -1;
    return rc;
  }

 private:
  int fd_{-1};
};

struct FileText {
  std::string text{};
  mode_t mode{0};
};

// Reads the whole file through one descriptor, so the permissions checked are those of the
// file read (no window for a swap between stat and open).
FileText read_file(const fs::path& path) {
  FileDescriptor fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (fd.get() < 0) {
    const int err = errno;
    throw std::runtime_error(fmt::format("cannot read key file {}: {}", path.string(),
                                         err == ENOENT ? "no such file" : errno_text(err)));
  }
  struct stat st {};
  if (::fstat(fd.get(), &st) != 0) {
    throw std::runtime_error(
        fmt::format("cannot stat key file {}: {}", path.string(), errno_text(errno)));
  }
  if (!S_ISREG(st.st_mode)) {
    throw std::runtime_error(fmt::format("key file {} is not a regular file", path.string()));
  }
  FileText out;
  out.mode = st.st_mode & 07777;
  std::array<char, 4096> buffer{};
  while (true) {
    const ssize_t n = ::read(fd.get(), buffer.data(), buffer.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      throw std::runtime_error(
          fmt::format("cannot read key file {}: {}", path.string(), errno_text(errno)));
    }
    if (n == 0) break;
    out.text.append(buffer.data(), static_cast<std::size_t>(n));
    // Key files are two lines; anything this large is not one.
    if (out.text.size() > 65536) {
      throw std::runtime_error(
          fmt::format("key file {} is too large to be a key file", path.string()));
    }
  }
  return out;
}

struct KeyFields {
  std::optional<std::string> public_z85{};
  std::optional<std::string> secret_z85{};
};

KeyFields parse_key_file(const fs::path& path, std::string_view text) {
  KeyFields fields;
  std::size_t line_number = 0;
  while (!text.empty()) {
    ++line_number;
    const std::size_t eol = text.find('\n');
    const std::string_view line = trim(text.substr(0, eol));
    text = eol == std::string_view::npos ? std::string_view{} : text.substr(eol + 1);
    if (line.empty() || line.front() == '#') continue;
    // '=' is a Z85 character: only the first one separates the field name.
    const std::size_t eq = line.find('=');
    if (eq == std::string_view::npos) {
      throw std::runtime_error(fmt::format("key file {} line {}: expected 'NAME = KEY', got '{}'",
                                           path.string(), line_number, line));
    }
    const std::string_view name = trim(line.substr(0, eq));
    const std::string value(trim(line.substr(eq + 1)));
    std::optional<std::string>* slot = nullptr;
    if (name == kPublicField) {
      slot = &fields.public_z85;
    } else if (name == kSecretField) {
      slot = &fields.secret_z85;
    } else {
      throw std::runtime_error(
          fmt::format("key file {} line {}: unknown field '{}' (expected {} or {})", path.string(),
                      line_number, name, kPublicField, kSecretField));
    }
    if (slot->has_value()) {
      throw std::runtime_error(
          fmt::format("key file {} line {}: {} given twice", path.string(), line_number, name));
    }
    if (const auto problem = z85_key_problem(value)) {
      throw std::runtime_error(
          fmt::format("key file {} line {}: {} is {}", path.string(), line_number, name, *problem));
    }
    *slot = value;
  }
  return fields;
}

// Writes `text` to a temporary beside `target` with `mode`, then moves it into place:
// rename() when replacing is allowed, link() otherwise (which fails if `target` exists, so a
// file created since the caller's check is not clobbered either).
void write_file_atomically(const fs::path& target, std::string_view text, mode_t mode,
                           bool replace) {
  std::string temp = target.string() + ".tmpXXXXXX";
  // mkstemp creates the file with mode 0600, so the secret is never readable by others.
  FileDescriptor fd(::mkstemp(temp.data()));
  if (fd.get() < 0) {
    throw std::runtime_error(
        fmt::format("cannot create {}: {}", target.string(), errno_text(errno)));
  }
  const auto fail = [&](const char* what, int err) {
    ::unlink(temp.c_str());
    throw std::runtime_error(
        fmt::format("cannot {} {}: {}", what, target.string(), errno_text(err)));
  };
  if (::fchmod(fd.get(), mode) != 0) fail("set the permissions of", errno);
  std::string_view rest = text;
  while (!rest.empty()) {
    const ssize_t n = ::write(fd.get(), rest.data(), rest.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      fail("write", errno);
    }
    rest.remove_prefix(static_cast<std::size_t>(n));
  }
  if (::fsync(fd.get()) != 0) fail("write", errno);
  if (fd.close() != 0) fail("write", errno);
  if (replace) {
    if (::rename(temp.c_str(), target.c_str()) != 0) fail("write", errno);
    return;
  }
  if (::link(temp.c_str(), target.c_str()) != 0) {
    const int err = errno;
    ::unlink(temp.c_str());
    if (err == EEXIST) {
      throw std::runtime_error(
          fmt::format("refusing to overwrite {} (use --force to replace it)", target.string()));
    }
    throw std::runtime_error(fmt::format("cannot write {}: {}", target.string(), errno_text(err)));
  }
  ::unlink(temp.c_str());
}

void require_valid_key(std::string_view endpoint, std::string_view what, std::string_view key) {
  if (const auto problem = z85_key_problem(key)) {
    throw std::invalid_argument(fmt::format("{}: {} is {}", endpoint, what, *problem));
  }
}

}  // namespace

CurveKeyPair generate_curve_keypair() {
  std::array<char, kZ85KeyChars + 1> pub{};
  std::array<char, kZ85KeyChars + 1> sec{};
  if (zmq_curve_keypair(pub.data(), sec.data()) != 0) {
    throw std::runtime_error(fmt::format("cannot generate a CURVE key pair: {}{}",
                                         zmq_strerror(zmq_errno()),
                                         zmq_has("curve") ? "" : " (libzmq built without CURVE)"));
  }
  return CurveKeyPair{std::string(pub.data(), kZ85KeyChars), std::string(sec.data(), kZ85KeyChars)};
}

std::string curve_public_from_secret(std::string_view secret_z85) {
  if (const auto problem = z85_key_problem(secret_z85)) {
    throw std::invalid_argument(fmt::format("secret key is {}", *problem));
  }
  const std::string secret(secret_z85);  // zmq_curve_public reads a NUL-terminated string
  std::array<char, kZ85KeyChars + 1> pub{};
  if (zmq_curve_public(pub.data(), secret.c_str()) != 0) {
    throw std::invalid_argument(
        fmt::format("cannot derive the public key: {}", zmq_strerror(zmq_errno())));
  }
  return std::string(pub.data(), kZ85KeyChars);
}

std::optional<std::string> z85_key_problem(std::string_view text) {
  if (text.size() != kZ85KeyChars) {
    return fmt::format("not a CURVE key: {} characters, expected {} Z85 characters", text.size(),
                       kZ85KeyChars);
  }
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (kZ85Alphabet.find(text[i]) == std::string_view::npos) {
      return fmt::format("not a CURVE key: character {} ('{}') is not Z85", i + 1, text[i]);
    }
  }
  // Z85 groups of five characters can spell values above 2^32; libzmq rejects those.
  const std::string terminated(text);
  std::array<std::uint8_t, kKeyBytes> bytes{};
  if (zmq_z85_decode(bytes.data(), terminated.c_str()) == nullptr) {
    return std::string("not a CURVE key: not valid Z85");
  }
  return std::nullopt;
}

KeyFilePaths key_file_paths(const fs::path& name) {
  return KeyFilePaths{fs::path(name.string() + ".key"), fs::path(name.string() + ".pub")};
}

KeyFilePaths write_key_files(const fs::path& name, const CurveKeyPair& keys, bool force) {
  if (const auto problem = z85_key_problem(keys.secret_z85)) {
    throw std::invalid_argument(fmt::format("secret key is {}", *problem));
  }
  if (curve_public_from_secret(keys.secret_z85) != keys.public_z85) {
    throw std::invalid_argument("the public key does not belong to the secret key");
  }
  const KeyFilePaths paths = key_file_paths(name);
  // Check both before writing either, so a refusal leaves no half-replaced pair.
  if (!force) {
    for (const fs::path& p : {paths.secret_file, paths.public_file}) {
      std::error_code ec;
      if (fs::exists(fs::symlink_status(p, ec))) {
        throw std::runtime_error(
            fmt::format("refusing to overwrite {} (use --force to replace it)", p.string()));
      }
    }
  }
  const std::string stem = name.filename().string();
  write_file_atomically(
      paths.secret_file,
      fmt::format("# teleop CURVE secret key '{}': keep private (mode 0600); "
                  "give {}.pub to the peer\n{} = {}\n{} = {}\n",
                  stem, stem, kPublicField, keys.public_z85, kSecretField, keys.secret_z85),
      0600, force);
  write_file_atomically(
      paths.public_file,
      fmt::format(
          "# teleop CURVE public key '{}': the peer lists it in "
          "security.client_public_keys (or as a node key) or uses it as the server key\n{} = {}\n",
          stem, kPublicField, keys.public_z85),
      0644, force);
  return paths;
}

LinkSecurity client_security(const std::string& secret_key_file, const std::string& server_key) {
  LinkSecurity sec;
  if (!secret_key_file.empty()) sec.own = load_secret_key_file(secret_key_file);
  if (!server_key.empty()) sec.server_public_key = load_public_key(server_key);
  return sec;
}

CurveKeyPair load_secret_key_file(const fs::path& path) {
  const FileText file = read_file(path);
  if ((file.mode & 077) != 0) {
    throw std::runtime_error(fmt::format(
        "secret key file {} has mode {:04o}: it must not be accessible by group or others "
        "(run: chmod 600 {})",
        path.string(), file.mode, path.string()));
  }
  const KeyFields fields = parse_key_file(path, file.text);
  if (!fields.secret_z85) {
    throw std::runtime_error(fmt::format("key file {} has no {} line (is it a .pub file?)",
                                         path.string(), kSecretField));
  }
  const std::string derived = curve_public_from_secret(*fields.secret_z85);
  if (fields.public_z85 && *fields.public_z85 != derived) {
    throw std::runtime_error(fmt::format(
        "key file {}: {} does not belong to {} (the file was edited or mixed up; derived public "
        "key is {})",
        path.string(), kPublicField, kSecretField, derived));
  }
  return CurveKeyPair{derived, *fields.secret_z85};
}

std::string load_public_key(std::string_view text_or_file) {
  const fs::path path{std::string(text_or_file)};
  std::error_code ec;
  // A file first: a 40-character path of Z85 characters (/tmp/xxxxxxxxxx/keys/master.pub)
  // is also a well-formed key, and taking it as one fails every handshake in silence.
  const bool is_file = fs::is_regular_file(path, ec);
  if (!is_file && !z85_key_problem(text_or_file)) return std::string(text_or_file);
  if (!is_file) {
    if (text_or_file.size() == kZ85KeyChars) {
      throw std::runtime_error(fmt::format("public key '{}' is {}", text_or_file,
                                           z85_key_problem(text_or_file).value_or("")));
    }
    throw std::runtime_error(
        fmt::format("public key '{}' is neither a 40-character Z85 key nor an existing key file",
                    text_or_file));
  }
  const KeyFields fields = parse_key_file(path, read_file(path).text);
  if (!fields.public_z85) {
    throw std::runtime_error(
        fmt::format("key file {} has no {} line", path.string(), kPublicField));
  }
  if (fields.secret_z85 && curve_public_from_secret(*fields.secret_z85) != *fields.public_z85) {
    throw std::runtime_error(fmt::format("key file {}: {} does not belong to {}", path.string(),
                                         kPublicField, kSecretField));
  }
  return *fields.public_z85;
}

namespace {

// 127.a.b.c, all four parts decimal 0..255.
bool is_ipv4_loopback(std::string_view host) {
  int parts = 0;
  while (true) {
    const std::size_t dot = host.find('.');
    const std::string_view part = host.substr(0, dot);
    unsigned value = 0;
    const auto [ptr, ec] = std::from_chars(part.data(), part.data() + part.size(), value);
    if (part.empty() || part.size() > 3 || ec != std::errc{} || ptr != part.data() + part.size() ||
        value > 255) {
      return false;
    }
    if (parts == 0 && value != 127) return false;
    ++parts;
    if (dot == std::string_view::npos) break;
    host.remove_prefix(dot + 1);
  }
  return parts == 4;
}

}  // namespace

bool is_loopback_endpoint(std::string_view endpoint) {
  if (endpoint.starts_with("ipc://") || endpoint.starts_with("inproc://")) return true;
  constexpr std::string_view kTcp = "tcp://";
  if (!endpoint.starts_with(kTcp)) return false;
  const std::string_view address = endpoint.substr(kTcp.size());
  if (address.find(';') != std::string_view::npos) return false;
  const std::size_t colon = address.rfind(':');
  if (colon == std::string_view::npos || colon + 1 == address.size()) return false;
  const std::string_view host = address.substr(0, colon);
  return host == "localhost" || host == "[::1]" || is_ipv4_loopback(host);
}

const char* to_string(LinkMechanism m) {
  switch (m) {
    case LinkMechanism::kPlaintext:
      return "plaintext";
    case LinkMechanism::kCurve:
      return "CURVE";
  }
  return "?";
}

LinkMechanism choose_mechanism(std::string_view endpoint, LinkRole role,
                               const LinkSecurity& security) {
  if (security.own) {
    require_valid_key(endpoint, "own public key", security.own->public_z85);
    require_valid_key(endpoint, "own secret key", security.own->secret_z85);
    if (curve_public_from_secret(security.own->secret_z85) != security.own->public_z85) {
      throw std::invalid_argument(
          fmt::format("{}: own public key does not belong to own secret key", endpoint));
    }
  }
  bool curve = false;
  if (role == LinkRole::kServer) {
    for (std::size_t i = 0; i < security.allowed_client_keys.size(); ++i) {
      require_valid_key(endpoint, fmt::format("allowed client key #{}", i + 1),
                        security.allowed_client_keys[i]);
    }
    if (security.own && security.allowed_client_keys.empty()) {
      throw std::invalid_argument(
          fmt::format("{}: CURVE server has a key pair but no allowed client keys: every client "
                      "would be refused (add the peer's public key)",
                      endpoint));
    }
    if (!security.own && !security.allowed_client_keys.empty()) {
      throw std::invalid_argument(
          fmt::format("{}: allowed client keys are set but the server has no key pair (set "
                      "master.node.secret_key_file / slave.node.secret_key_file)",
                      endpoint));
    }
    curve = security.own.has_value();
  } else {
    if (security.server_public_key) {
      require_valid_key(endpoint, "server public key", *security.server_public_key);
    }
    if (security.own && !security.server_public_key) {
      throw std::invalid_argument(
          fmt::format("{}: CURVE client has a key pair but no server public key (set the "
                      "peer's public key)",
                      endpoint));
    }
    if (!security.own && security.server_public_key) {
      throw std::invalid_argument(
          fmt::format("{}: a server public key is set but the client has no key pair (set "
                      "master.node.secret_key_file / slave.node.secret_key_file)",
                      endpoint));
    }
    curve = security.own.has_value();
  }
  if (curve) return LinkMechanism::kCurve;
  if (!security.insecure && !is_loopback_endpoint(endpoint)) {
    throw std::invalid_argument(
        fmt::format("{} is not a loopback endpoint: CURVE keys are required (set "
                    "master.node.secret_key_file / slave.node.secret_key_file and the public "
                    "keys in security) or security.insecure: true to send plaintext",
                    endpoint));
  }
  return LinkMechanism::kPlaintext;
}

LinkMechanism apply_link_security(zmq::context_t& ctx, zmq::socket_t& socket,
                                  std::string_view endpoint, LinkRole role,
                                  const LinkSecurity& security) {
  const LinkMechanism mechanism = choose_mechanism(endpoint, role, security);
  if (mechanism == LinkMechanism::kPlaintext) return mechanism;
  if (role == LinkRole::kServer) {
    ZapHandler* const zap = ZapHandler::serving(ctx);
    if (zap == nullptr) {
      throw std::invalid_argument(
          fmt::format("{}: a CURVE server needs a ZapHandler on its context to enforce the "
                      "allowed client keys (without one libzmq accepts any client)",
                      endpoint));
    }
    socket.set(zmq::sockopt::curve_server, true);
    socket.set(zmq::sockopt::curve_secretkey, security.own->secret_z85);
    socket.set(zmq::sockopt::curve_publickey, security.own->public_z85);
    socket.set(zmq::sockopt::zap_domain,
               zap->add_domain(std::string(endpoint), security.allowed_client_keys));
  } else {
    socket.set(zmq::sockopt::curve_serverkey, *security.server_public_key);
    socket.set(zmq::sockopt::curve_publickey, security.own->public_z85);
    socket.set(zmq::sockopt::curve_secretkey, security.own->secret_z85);
  }
  return mechanism;
}

}  // namespace teleop::transport
