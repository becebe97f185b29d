// The TSan build's canary (scripts/sanitize tsan runs it after the suite): a race it must report.
// The TSan setup hides what gRPC's uninstrumented libraries do (tsan.ignorelist, tsan.supp,
// ignore_noninstrumented_modules); this proves it still sees a race in our code when that code
// runs on gRPC's threads, as every reactor callback does. A server reactor, started on a gRPC
// thread for each call, bumps a plain counter that a thread of ours also bumps, with no lock.
// Under TSan (halt_on_error=1) the program must stop with a report naming BumpUnlocked; without
// a report it exits 0, and scripts/sanitize fails the run.
#include <atomic>
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>

#include "grpcpp/generic/async_generic_service.h"
#include "grpcpp/generic/generic_stub.h"
#include "grpcpp/grpcpp.h"

namespace {

long counter = 0;  // deliberately unguarded

__attribute__((noinline)) void BumpUnlocked() { counter = counter + 1; }

class Reactor final : public grpc::ServerGenericBidiReactor {
 public:
  Reactor() {
    BumpUnlocked();  // on a gRPC callback thread
    Finish(grpc::Status::OK);
  }
  void OnDone() override { delete this; }
};

class Service final : public grpc::CallbackGenericService {
  grpc::ServerGenericBidiReactor* CreateReactor(grpc::GenericCallbackServerContext*) override {
    return new Reactor;
  }
};

}  // namespace

int main() {
  Service service;
  int port = 0;
  grpc::ServerBuilder builder;
  builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port);
  builder.RegisterCallbackGenericService(&service);
  std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
  if (server == nullptr || port == 0) {
    std::fprintf(stderr, "tsan_canary: cannot start a server on 127.0.0.1\n");
    return 2;
  }

  std::atomic<bool> stop{false}, started{false};
  std::thread ours([&] {
    BumpUnlocked();
    started = true;
    // A bump every 100 us, not a tight loop: TSan reports a race only when it can restore the
    // earlier access's stack from that thread's trace, and millions of bumps between two calls
    // wrap the trace (a spinning thread made 6 of 6 runs miss the race on a loaded machine).
    while (!stop.load(std::memory_order_relaxed)) {
      BumpUnlocked();
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
  });
  while (!started) std::this_thread::yield();  // both sides bump from the first call on
  auto channel = grpc::CreateChannel("127.0.0.1:" + std::to_string(port),
                                     grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  // Up to 200 calls (halt_on_error stops at the first report); scripts/sanitize gives the canary
  // three runs. With the paced bumps above TSan reported the race in 10 of 10 runs on a loaded
  // machine (the tight loop before: 0 of 6 there, about 1 miss in 20 on a quiet one).
  for (int i = 0; i < 200; ++i) {
    grpc::ClientContext context;
    grpc::Slice payload(std::string("bump"));
    grpc::ByteBuffer request(&payload, 1), reply;  // an empty ByteBuffer is no message at all
    std::atomic<bool> done{false};
    stub.UnaryCall(&context, "/canary/Bump", grpc::StubOptions(), &request, &reply,
                   [&](grpc::Status) { done = true; });
    while (!done) std::this_thread::yield();
  }
  stop = true;
  ours.join();
  server->Shutdown();
  std::printf("tsan_canary: no report: %ld bumps raced unseen\n", counter);
  return 0;
}
