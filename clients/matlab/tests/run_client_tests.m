function run_client_tests()
% run_client_tests  The MATLAB/Octave client against a running `thermode serve` (the simulated display) at
% THERMODE_URL with the token THERMODE_TOKEN: every request, the replies the daemon gives, and its refusals raised
% as errors thermode:<code>. Prints one line per check; any failure is an error (octave-cli exits non-zero).
% Run by the Rust test `matlab_client` of the thermode CLI (crates/thermode/tests/cli/matlab_client.rs), which
% starts the daemon; by hand:
%   THERMODE_URL=http://127.0.0.1:8765 octave-cli --eval "addpath('clients/matlab', 'clients/matlab/tests'); run_client_tests"

url = getenv('THERMODE_URL');
token = getenv('THERMODE_TOKEN');
d = ThermodeClient(url, 'Token', token, 'Timeout', 10);

s = d.status();
check(strcmp(s.type, 'status') && s.channel_count == 5, 'status: five channels');
check(s.auth.token_required == ~isempty(token), 'status: the token requirement as started');

r = d.touch(1, 'aluminium');
check(strcmp(r.type, 'ok') && strcmp(r.request, 'touch') && r.channel == 1, 'touch: ok');
check(strcmp(r.material, 'aluminium') && r.object_temp_c == 23, 'touch: aluminium at 23 degC');
s = d.status();
check(strcmp(s.channels(2).mode, 'touch') && strcmp(s.channels(2).material, 'aluminium'), ...
      'status after touch: channel 1 touches aluminium');
check(strcmp(s.channels(2).owner.kind, 'client') && s.channels(2).owner.id == s.http.command_client, ...
      'status after touch: owned by the HTTP lease');

r = d.touch(2, struct('name', 'my-foam', 'conductivity_w_mk', 0.03, 'density_kg_m3', 30, ...
                      'specific_heat_j_kgk', 1400), 'ObjectTempC', 30);
check(strcmp(r.material, 'my-foam') && r.object_temp_c == 30, 'touch: custom properties at 30 degC');

r = d.setpoint(3, 30, 2);
check(strcmp(r.request, 'setpoint') && r.temp_c == 30, 'setpoint: 30 degC at 2 degC/s');
s = d.status();
check(strcmp(s.channels(4).mode, 'direct') && s.channels(4).direct_temp_c == 30, 'status after setpoint: direct');

r = d.release(1);
check(strcmp(r.request, 'release'), 'release: ok');
s = d.status();
check(strcmp(s.channels(2).mode, 'air'), 'status after release: air');

r = d.marker('trial 1 start', 0);
check(strcmp(r.request, 'marker') && r.channel == 0 && isnumeric(r.time_s), 'marker: stamped with the loop time');

% A method-of-limits run, fast: down at 10 degC/s until the response, back at 20 degC/s.
r = retry_busy(@() d.program(0, {ThermodeClient.ramp(15, 10, true), ThermodeClient.ramp(32, 20)}));
check(strcmp(r.request, 'program') && isequal(r.channels(:)', 0), 'program: started on channel 0');
pause(0.5);
p = d.response(0);
check(strcmp(p.request, 'response') && strcmp(p.kind, 'button'), 'response: a button press');
check(p.ended_segment == 0, 'response: ended the until-response ramp');
check(p.setpoint_c < 31.5 && p.setpoint_c > 15, sprintf('response: the set-point at the press (%.2f degC)', p.setpoint_c));
s = d.wait_for_program_end(0, 20);
check(isempty(s.channels(1).program_segment), 'wait_for_program_end: the program ended');

r = d.program(4, [ThermodeClient.hold(5, true)]);
r = d.program_stop(4);
check(strcmp(r.request, 'program_stop'), 'program_stop: ok');

r = d.stop_all();
check(strcmp(r.request, 'stop_all'), 'stop_all: ok');
s = d.status();
check(all([s.channels.held_off]) && all(strcmp({s.channels.mode}, 'air')), 'status after stop_all: all held off');

expect_error(@() d.touch(1, 'unobtainium'), 'thermode:unknown_material');
expect_error(@() d.touch(9, 'wood'), 'thermode:unknown_channel');
expect_error(@() d.setpoint(0, 60, 1), 'thermode:bad_value');
expect_error(@() d.request('subscribe', struct('rate_hz', 10)), 'thermode:unknown_type');
if ~isempty(token)
  wrong = ThermodeClient(url, 'Token', [token, 'x']);
  expect_error(@() wrong.status(), 'thermode:unauthorized');
  none = ThermodeClient(url, 'Token', '');
  expect_error(@() none.touch(0, 'wood'), 'thermode:unauthorized');
end
nobody = ThermodeClient('http://127.0.0.1:9', 'Timeout', 2);
expect_error(@() nobody.status(), 'thermode:connection');
fprintf('all MATLAB/Octave client checks passed\n');
end

function check(condition, what)
if ~condition
  error('client_test:failed', 'FAILED: %s', what);
end
fprintf('ok: %s\n', what);
end

function expect_error(action, identifier)
try
  action();
catch e
  if strcmp(e.identifier, identifier)
    fprintf('ok: raises %s (%s)\n', identifier, e.message);
    return;
  end
  error('client_test:failed', 'FAILED: expected %s, got %s: %s', identifier, e.identifier, e.message);
end
error('client_test:failed', 'FAILED: expected %s, got no error', identifier);
end

function reply = retry_busy(action)
% A program needs the channel's first reading: `busy` until then.
for attempt = 1:50
  try
    reply = action();
    return;
  catch e
    if ~strcmp(e.identifier, 'thermode:busy')
      rethrow(e);
    end
    pause(0.1);
  end
end
error('client_test:failed', 'FAILED: still busy after 50 attempts');
end
