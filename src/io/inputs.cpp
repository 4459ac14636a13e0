// brume — every input is a regular file within its limits before anything is
// read (issue #51): opened with O_NONBLOCK, so that a FIFO cannot hang the
// open, then fstat'ed. A directory read as a stream is empty (`--points .`
// was 0 points, exit 0), /dev/zero never ends (a scan grew ~0.7 GB/s until
// the kernel killed it; an image or a record's hash spun forever), a FIFO
// blocks until a writer comes (one in a batch manifest hung the batch).
// Refusing what is not a regular file also refuses /dev/stdin and a shell's
// <(...): every input is hashed into its run's record, which a stream
// cannot be (docs/reliability.md).
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

#include "brume/error.hpp"
#include "brume/io.hpp"

namespace brume {

namespace {

std::string input_size_text(std::uint64_t bytes) {
  char b[64];
  if (bytes < 1024)
    std::snprintf(b, sizeof b, "%llu bytes", static_cast<unsigned long long>(bytes));
  else if (bytes < 1024ull * 1024)
    std::snprintf(b, sizeof b, "%.1f KiB", static_cast<double>(bytes) / 1024.0);
  else if (bytes < 1024ull * 1024 * 1024)
    std::snprintf(b, sizeof b, "%.1f MiB", static_cast<double>(bytes) / (1024.0 * 1024.0));
  else
    std::snprintf(b, sizeof b, "%.1f GiB", static_cast<double>(bytes) / (1024.0 * 1024.0 * 1024.0));
  return b;
}

std::string input_kind_of(mode_t m) {
  if (S_ISDIR(m)) return "a directory";
  if (S_ISCHR(m)) return "a character device";
  if (S_ISBLK(m)) return "a block device";
  if (S_ISFIFO(m)) return "a FIFO (a named pipe, /dev/stdin or a shell's <(...))";
  if (S_ISSOCK(m)) return "a socket";
  return "not a regular file";
}

}  // namespace

std::string input_name(const std::string& path, const std::string& what) {
  return (what.empty() ? std::string() : what + " ") + "'" + path + "'";
}

InputFile::InputFile(const std::string& path, const std::string& what, const InputLimit& limit) {
  const std::string name = input_name(path, what);
  if (path.empty()) throw Error("cannot read " + (what.empty() ? std::string("an input") : what) + ": no file named");
  // O_NONBLOCK: opening a FIFO for reading returns at once instead of waiting
  // for a writer; it changes nothing for a regular file.
  fd_ = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd_ < 0) {
    const int e = errno;
    if (e == ENOENT || e == ENOTDIR) throw FileNotFound("cannot read " + name + ": no such file");
    throw Error("cannot read " + name + ": " + std::strerror(e));
  }
  struct stat st {};
  if (::fstat(fd_, &st) != 0) {
    const int e = errno;
    ::close(fd_);
    fd_ = -1;
    throw Error("cannot read " + name + ": " + std::strerror(e));
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd_);
    fd_ = -1;
    if (S_ISDIR(st.st_mode)) throw Error("cannot read " + name + ": it is a directory, not a file");
    throw Error("cannot read " + name + ": it is " + input_kind_of(st.st_mode) +
                ", not a regular file. brume reads its inputs from regular files only, because every input is "
                "hashed into the run's record: write the data to a file first and name that file");
  }
  size_ = static_cast<std::uint64_t>(st.st_size);
  if (size_ > limit.max_bytes) {
    ::close(fd_);
    fd_ = -1;
    throw Error("cannot read " + name + ": it is " + input_size_text(size_) + ", over the limit of " +
                input_size_text(limit.max_bytes) + (limit.reason.empty() ? std::string() : " (" + limit.reason + ")") +
                "; is it the right file?");
  }
  // A regular file reads the same without O_NONBLOCK; clear it for the
  // readers that take the descriptor over.
  const int flags = ::fcntl(fd_, F_GETFL);
  if (flags >= 0) ::fcntl(fd_, F_SETFL, flags & ~O_NONBLOCK);
  name_ = name;
}

InputFile::~InputFile() {
  if (fd_ >= 0) ::close(fd_);
}

void InputFile::read_all(char* dst, std::uint64_t bytes) {
  std::uint64_t got = 0;
  while (got < bytes) {
    const ssize_t n = ::read(fd_, dst + got, static_cast<std::size_t>(std::min<std::uint64_t>(bytes - got, 1u << 30)));
    if (n < 0) {
      if (errno == EINTR) continue;
      throw Error("cannot read " + name_ + ": " + std::strerror(errno));
    }
    if (n == 0)
      throw Error("cannot read " + name_ + ": it ended after " + input_size_text(got) + " of the " + input_size_text(bytes) +
                  " it held when opened (was it changed while brume read it?)");
    got += static_cast<std::uint64_t>(n);
  }
}

std::string InputFile::read_text(const InputLimit& limit) {
  check_memory(2 * size_ + 4096, "reading " + name_);  // the text and what its parser makes of it, about as much
  std::string s(static_cast<std::size_t>(size_), '\0');
  read_all(s.data(), size_);
  // A file that grew since fstat (or a kernel file whose size says 0, as
  // /proc's do): the rest, up to the limit.
  char more[4096];
  for (;;) {
    const ssize_t n = ::read(fd_, more, sizeof more);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    s.append(more, static_cast<std::size_t>(n));
    if (s.size() > limit.max_bytes)
      throw Error("cannot read " + name_ + ": it grew past the limit of " + input_size_text(limit.max_bytes) +
                  (limit.reason.empty() ? std::string() : " (" + limit.reason + ")") + " while it was read");
  }
  return s;
}

void check_input_file(const std::string& path, const std::string& what, const InputLimit& limit) {
  InputFile f(path, what, limit);
}

std::string read_input_file(const std::string& path, const std::string& what, const InputLimit& limit) {
  InputFile f(path, what, limit);
  return f.read_text(limit);
}

}  // namespace brume
