// Runs a real isostreamd for the integration tests: on 127.0.0.1 with port 0, the port read
// from its "listening on HOST:PORT" line, stopped (SIGTERM, then SIGKILL) at the end.
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

namespace isostream::testing {

class ScratchDir {
 public:
  ScratchDir() {
    std::string pattern = std::filesystem::temp_directory_path().string() + "/isostreamd_XXXXXX";
    path_ = mkdtemp(pattern.data()) ? pattern : std::string();
  }
  ~ScratchDir() {
    std::error_code ignored;
    if (!path_.empty()) std::filesystem::remove_all(path_, ignored);
  }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

class DaemonProcess {
 public:
  DaemonProcess() = default;
  DaemonProcess(const DaemonProcess&) = delete;
  DaemonProcess& operator=(const DaemonProcess&) = delete;
  ~DaemonProcess() { Kill(); }

  // Starts isostreamd with `args` plus --listen 127.0.0.1:0; returns once it printed its port
  // (false after `timeout` or if it exited). Its log goes to `log_path`.
  bool Start(const std::vector<std::string>& args, const std::string& log_path,
             std::chrono::milliseconds timeout = std::chrono::seconds(30)) {
    int out[2];
    if (pipe(out) != 0) return false;
    pid_ = fork();
    if (pid_ < 0) return false;
    if (pid_ == 0) {
      dup2(out[1], STDOUT_FILENO);
      const int log = open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (log >= 0) dup2(log, STDERR_FILENO);
      close(out[0]);
      close(out[1]);
      std::vector<std::string> all = {ISOSTREAMD_PATH, "--listen", "127.0.0.1:0"};
      all.insert(all.end(), args.begin(), args.end());
      std::vector<char*> argv;
      for (auto& a : all) argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
    close(out[1]);
    stdout_ = out[0];
    const auto until = std::chrono::steady_clock::now() + timeout;
    std::string text;
    while (std::chrono::steady_clock::now() < until) {
      pollfd p{stdout_, POLLIN, 0};
      if (poll(&p, 1, 100) <= 0) continue;
      char buf[256];
      const ssize_t n = read(stdout_, buf, sizeof buf);
      if (n <= 0) return false;  // exited
      text.append(buf, size_t(n));
      const size_t at = text.find("listening on 127.0.0.1:");
      const size_t eol = text.find('\n', at == std::string::npos ? 0 : at);
      if (at != std::string::npos && eol != std::string::npos) {
        port_ = std::atoi(text.c_str() + at + 23);
        return port_ > 0;
      }
    }
    return false;
  }

  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  pid_t pid() const { return pid_; }

  // Sends `sig` and waits (bounded) for the exit; returns the exit code, or -1 if it did not
  // exit normally in time (it is then killed).
  int Stop(int sig = SIGTERM, std::chrono::milliseconds timeout = std::chrono::seconds(15)) {
    if (pid_ <= 0) return -1;
    kill(pid_, sig);
    const auto until = std::chrono::steady_clock::now() + timeout;
    int status = 0;
    while (std::chrono::steady_clock::now() < until) {
      const pid_t r = waitpid(pid_, &status, WNOHANG);
      if (r == pid_) {
        pid_ = -1;
        CloseOut();
        return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    Kill();
    return -1;
  }

  void Kill() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
      pid_ = -1;
    }
    CloseOut();
  }

 private:
  void CloseOut() {
    if (stdout_ >= 0) close(stdout_);
    stdout_ = -1;
  }
  pid_t pid_ = -1;
  int stdout_ = -1;
  int port_ = 0;
};

// A self-signed certificate for 127.0.0.1 and localhost in `dir` (key.pem, cert.pem), made by
// openssl; false if openssl cannot make one (the caller skips its TLS test then).
inline bool MakeTestCertificate(const std::string& dir, std::string* key, std::string* cert) {
  *key = dir + "/key.pem";
  *cert = dir + "/cert.pem";
  const std::string make =
      "openssl req -x509 -newkey rsa:2048 -nodes -keyout " + *key + " -out " + *cert +
      " -days 1 -subj /CN=localhost -addext subjectAltName=IP:127.0.0.1,DNS:localhost "
      ">/dev/null 2>&1";
  return std::system(make.c_str()) == 0;
}

}  // namespace isostream::testing
