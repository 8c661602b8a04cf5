#include "common/core/command_line.hpp"

namespace teleop::cli {

bool ArgCursor::next() {
  if (has_inline_value_ && !inline_value_taken_) {
    throw UsageError(flag_ + " takes no value (got '" + args_[i_] + "')");
  }
  has_inline_value_ = false;
  inline_value_taken_ = false;
  if (++i_ >= args_.size()) {
    i_ = args_.size();
    return false;
  }
  const std::string& a = args_[i_];
  const std::size_t eq = a.find('=');
  if (a.rfind("--", 0) == 0 && eq != std::string::npos && eq > 2) {
    flag_ = a.substr(0, eq);
    inline_value_ = a.substr(eq + 1);
    has_inline_value_ = true;
  } else {
    flag_ = a;
  }
  return true;
}

const std::string& ArgCursor::value(const char* flag) {
  if (has_inline_value_) {
    inline_value_taken_ = true;
    return inline_value_;
  }
  if (i_ + 1 >= args_.size()) throw UsageError(std::string(flag) + " needs a value");
  return args_[++i_];
}

}  // namespace teleop::cli
