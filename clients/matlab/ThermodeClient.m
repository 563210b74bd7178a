% ThermodeClient  A client of the thermode daemon (`thermode serve`) for MATLAB R2019b+ and GNU Octave 7+.
%
% It posts each request to the daemon's HTTP command route (POST /api/command, docs/api.md): the same requests,
% replies and errors as the WebSocket API, with no WebSocket library. Every method returns the daemon's reply as a
% struct (jsondecode of its JSON); a refusal is raised as a MATLAB error whose identifier is `thermode:<code>`
% with the daemon's error code (thermode:unknown_material, thermode:unauthorized, thermode:rate_limited, ...), and
% a daemon that cannot be reached as `thermode:connection`.
%
%   d = ThermodeClient('http://127.0.0.1:8765');          % 'Token', T for `serve --token T`
%   d.touch(1, 'aluminium');                              % the index finger touches aluminium at 23 degC
%   s = d.status(); disp(s.channels(2).skin_c)            % channels are numbered from 0: channels(2) is channel 1
%   d.release(1);
%
% Channels are numbered from 0 as on the wire; temperatures in degC, rates in degC/s, times in s.
%
% Contacts made over HTTP live on a lease (docs/api.md, HTTP commands): the daemon releases them after its
% --command-lease (30 s by default) plus the grace period without any request from an HTTP client, so a script
% that crashes leaves nothing touching. A script that waits longer than that between requests calls status()
% now and then (wait_for_program_end does).
%
% MATLAB sends with matlab.net.http; Octave (whose webwrite cannot post a JSON body) through the `curl` program
% (the 'Transport' option chooses: 'auto', 'matlab' or 'curl').

classdef ThermodeClient < handle
  properties (SetAccess = private)
    % Base address of the daemon, e.g. 'http://127.0.0.1:8765' (default).
    Url = 'http://127.0.0.1:8765';
    % Longest wait for one reply [s] (default 10).
    Timeout = 10;
    % 'matlab' (matlab.net.http) or 'curl'; chosen from 'auto' by the constructor.
    Transport = 'auto';
  end
  properties (Access = private)
    % The daemon's token ('' when it needs none; default: the THERMODE_TOKEN environment variable).
    Token = '';
    % The id of the next request.
    NextId = 1;
  end

  methods
    function obj = ThermodeClient(url, varargin)
      % ThermodeClient(URL, 'Token', T, 'Timeout', S, 'Transport', 'auto'|'matlab'|'curl')
      if nargin >= 1 && ~isempty(url)
        obj.Url = regexprep(char(url), '/+$', '');
      end
      obj.Token = getenv('THERMODE_TOKEN');
      for k = 1:2:numel(varargin)
        name = lower(char(varargin{k}));
        if k + 1 > numel(varargin)
          error('thermode:bad_argument', 'option %s needs a value', name);
        end
        value = varargin{k + 1};
        switch name
          case 'token'
            obj.Token = char(value);
          case 'timeout'
            obj.Timeout = double(value);
          case 'transport'
            obj.Transport = lower(char(value));
          otherwise
            error('thermode:bad_argument', 'unknown option %s (Token, Timeout, Transport)', name);
        end
      end
      if strcmp(obj.Transport, 'auto')
        if ThermodeClient.is_octave()
          obj.Transport = 'curl';
        else
          obj.Transport = 'matlab';
        end
      end
      if ~any(strcmp(obj.Transport, {'matlab', 'curl'}))
        error('thermode:bad_argument', 'Transport must be auto, matlab or curl, not %s', obj.Transport);
      end
    end

    function reply = touch(obj, channel, material, varargin)
      % touch(CHANNEL, MATERIAL, 'ObjectTempC', C): MATERIAL a library name ('aluminium', 'wood', ...) or a struct
      % of properties (conductivity_w_mk, density_kg_m3, specific_heat_j_kgk, optional thickness_m and name).
      % The object is at C degC (default: the daemon's, 23).
      msg = struct('channel', channel);
      if ischar(material) || isstring(material)
        msg.material = char(material);
      else
        msg.properties = material;
      end
      for k = 1:2:numel(varargin)
        switch lower(char(varargin{k}))
          case 'objecttempc'
            msg.object_temp_c = varargin{k + 1};
          otherwise
            error('thermode:bad_argument', 'unknown option %s (ObjectTempC)', char(varargin{k}));
        end
      end
      reply = obj.request('touch', msg);
    end

    function reply = release(obj, channel)
      % release(CHANNEL): the channel renders air again.
      reply = obj.request('release', struct('channel', channel));
    end

    function reply = setpoint(obj, channel, temp_c, rate_c_s)
      % setpoint(CHANNEL, TEMP_C, RATE_C_S): the display ramps to TEMP_C degC at RATE_C_S degC/s (direct mode).
      reply = obj.request('setpoint', struct('channel', channel, 'temp_c', temp_c, 'rate_c_s', rate_c_s));
    end

    function reply = program(obj, varargin)
      % program(CHANNEL, SEGMENTS, CHANNEL2, SEGMENTS2, ...): runs a stimulus program, every channel starting on
      % one loop tick. SEGMENTS is a cell array (or struct array) of ThermodeClient.ramp/step/hold segments.
      if isempty(varargin) || mod(numel(varargin), 2) ~= 0
        error('thermode:bad_argument', 'program takes pairs of a channel and its segments');
      end
      parts = cell(1, numel(varargin) / 2);
      for k = 1:2:numel(varargin)
        parts{(k + 1) / 2} = sprintf('"%d":%s', round(varargin{k}), ThermodeClient.segments_json(varargin{k + 1}));
      end
      channels = ['{', strjoin(parts, ','), '}'];
      reply = obj.request('program', struct('channels', '@@channels@@'), channels);
    end

    function reply = program_stop(obj, channel)
      % program_stop(CHANNEL): ends the channel's program; its set-point holds where it stood.
      reply = obj.request('program_stop', struct('channel', channel));
    end

    function reply = response(obj, channel, kind, value)
      % response(CHANNEL): a button press; response(CHANNEL, 'rating', VALUE) a rating from 0 to 100. The reply
      % gives the plate at the tick the response took effect (sensor_c, setpoint_c, ended_segment).
      if nargin < 3 || isempty(kind)
        kind = 'button';
      end
      msg = struct('channel', channel, 'kind', char(kind));
      if nargin >= 4
        msg.value = value;
      end
      reply = obj.request('response', msg);
    end

    function reply = stop_all(obj)
      % stop_all(): every channel released and its drive held at 0 A until its next command.
      reply = obj.request('stop_all', struct());
    end

    function reply = clear_fault(obj, channel)
      % clear_fault(CHANNEL): clears a latched safety fault once its cause is gone.
      reply = obj.request('clear_fault', struct('channel', channel));
    end

    function reply = status(obj)
      % status(): the daemon's status (reply.channels(c + 1) is channel c). Also renews the HTTP lease.
      reply = obj.request('status', struct());
    end

    function reply = marker(obj, text, channel)
      % marker(TEXT) or marker(TEXT, CHANNEL): an event marker stamped with the daemon's loop clock (and sent on
      % the LSL marker stream under `serve --lsl`).
      msg = struct('text', char(text));
      if nargin >= 3
        msg.channel = channel;
      end
      reply = obj.request('marker', msg);
    end

    function reply = ack_recording(obj)
      % ack_recording(): an operator acknowledges a failed recording.
      reply = obj.request('ack_recording', struct());
    end

    function status = wait_for_program_end(obj, channel, timeout_s)
      % wait_for_program_end(CHANNEL, TIMEOUT_S): polls the status (every 0.1 s, renewing the lease) until the
      % channel runs no program; returns that status; thermode:timeout after TIMEOUT_S s (default 60).
      if nargin < 3
        timeout_s = 60;
      end
      started = tic;
      while true
        status = obj.status();
        if isempty(status.channels(channel + 1).program_segment)
          return;
        end
        if toc(started) > timeout_s
          error('thermode:timeout', 'channel %d still runs its program after %g s', channel, timeout_s);
        end
        pause(0.1);
      end
    end

    function reply = request(obj, type, fields, channels_json)
      % request(TYPE, FIELDS): sends any request (a struct of its fields without type and id) and returns the
      % reply; a refusal raises thermode:<code>.
      msg = struct('type', char(type), 'id', obj.NextId);
      names = fieldnames(fields);
      for k = 1:numel(names)
        msg.(names{k}) = fields.(names{k});
      end
      obj.NextId = obj.NextId + 1;
      text = jsonencode(msg);
      if nargin >= 4
        text = strrep(text, '"@@channels@@"', channels_json);
      end
      [status_code, body] = obj.post(text);
      reply = ThermodeClient.decode(status_code, body);
    end
  end

  methods (Static)
    function segment = ramp(to_c, rate_c_s, until_response)
      % ramp(TO_C, RATE_C_S, UNTIL_RESPONSE): to TO_C degC at RATE_C_S degC/s; with UNTIL_RESPONSE true it ends
      % early at the participant's response.
      segment = struct('to_c', to_c, 'rate_c_s', rate_c_s);
      if nargin >= 3 && until_response
        segment.until = 'response';
      end
    end

    function segment = step(to_c)
      % step(TO_C): to TO_C degC as fast as the display allows.
      segment = struct('to_c', to_c);
    end

    function segment = hold(hold_s, until_response)
      % hold(HOLD_S, UNTIL_RESPONSE): the set-point stays for HOLD_S s (with UNTIL_RESPONSE, at most that long).
      segment = struct('hold_s', hold_s);
      if nargin >= 2 && until_response
        segment.until = 'response';
      end
    end

    function yes = is_octave()
      % Whether this runs under GNU Octave.
      yes = exist('OCTAVE_VERSION', 'builtin') > 0;
    end
  end

  methods (Static, Access = private)
    function text = segments_json(segments)
      % A JSON array of segments (a cell array or a struct array; one struct is one segment).
      if isstruct(segments)
        segments = num2cell(segments);
      end
      parts = cellfun(@jsonencode, segments, 'UniformOutput', false);
      text = ['[', strjoin(parts, ','), ']'];
    end

    function reply = decode(status_code, body)
      % The reply of BODY (an HTTP response with STATUS_CODE); raises thermode:<code> for an error reply.
      try
        reply = jsondecode(body);
      catch
        error('thermode:bad_reply', 'the daemon answered HTTP %d with something that is not JSON: %s', ...
              status_code, body(1:min(end, 200)));
      end
      if isstruct(reply) && isfield(reply, 'type') && strcmp(reply.type, 'error')
        error(['thermode:', reply.code], '%s', reply.message);
      end
    end
  end

  methods (Access = private)
    function [status_code, body] = post(obj, text)
      % POSTs TEXT to /api/command: the HTTP status and the response body.
      url = [obj.Url, '/api/command'];
      if strcmp(obj.Transport, 'matlab')
        [status_code, body] = ThermodeClient.post_matlab(url, text, obj.Token, obj.Timeout);
      else
        [status_code, body] = ThermodeClient.post_curl(url, text, obj.Token, obj.Timeout);
      end
    end
  end

  methods (Static, Access = private)
    function [status_code, body] = post_matlab(url, text, token, timeout_s)
      % matlab.net.http: the body sent as raw UTF-8 bytes, the response kept raw (never converted).
      headers = matlab.net.http.field.ContentTypeField('application/json');
      if ~isempty(token)
        headers = [headers, matlab.net.http.HeaderField('Authorization', ['Bearer ', token])];
      end
      message = matlab.net.http.RequestMessage('POST', headers, matlab.net.http.MessageBody());
      message.Body.Payload = unicode2native(text, 'UTF-8');
      options = matlab.net.http.HTTPOptions('ConnectTimeout', timeout_s, 'ResponseTimeout', timeout_s, ...
                                            'ConvertResponse', false, 'SavePayload', true);
      try
        response = message.send(matlab.net.URI(url), options);
      catch e
        error('thermode:connection', 'cannot reach the daemon at %s: %s', url, e.message);
      end
      status_code = double(response.StatusCode);
      body = native2unicode(reshape(uint8(response.Body.Payload), 1, []), 'UTF-8');
    end

    function [status_code, body] = post_curl(url, text, token, timeout_s)
      % The curl program: the request body and headers in temporary files (the token never on a command line),
      % the response body into a file, the HTTP status on standard output.
      files = struct('body', [tempname(), '.json'], 'headers', [tempname(), '.txt'], ...
                     'reply', [tempname(), '.json'], 'errors', [tempname(), '.txt']);
      cleanup = onCleanup(@() ThermodeClient.remove_files(files));
      ThermodeClient.write_file(files.body, text);
      header_lines = sprintf('Content-Type: application/json\n');
      if ~isempty(token)
        header_lines = [header_lines, sprintf('Authorization: Bearer %s\n', token)];
      end
      ThermodeClient.write_file(files.headers, header_lines);
      command = sprintf(['curl -sS -X POST --max-time %g -H "@%s" --data-binary "@%s" -o "%s" ', ...
                         '-w "%%{http_code}" "%s" 2>"%s"'], ...
                        timeout_s, files.headers, files.body, files.reply, url, files.errors);
      [exit_code, output] = system(command);
      if exit_code ~= 0
        error('thermode:connection', 'cannot reach the daemon at %s (curl exit %d): %s', url, exit_code, ...
              strtrim(ThermodeClient.read_file(files.errors)));
      end
      status_code = str2double(strtrim(output));
      body = ThermodeClient.read_file(files.reply);
    end

    function write_file(path, text)
      fid = fopen(path, 'w');
      if fid < 0
        error('thermode:connection', 'cannot write the temporary file %s', path);
      end
      fwrite(fid, unicode2native(text, 'UTF-8'));
      fclose(fid);
    end

    function text = read_file(path)
      fid = fopen(path, 'r');
      if fid < 0
        text = '';
        return;
      end
      bytes = fread(fid, Inf, 'uint8=>uint8');
      fclose(fid);
      text = native2unicode(reshape(bytes, 1, []), 'UTF-8');
    end

    function remove_files(files)
      names = struct2cell(files);
      for k = 1:numel(names)
        if exist(names{k}, 'file')
          delete(names{k});
        end
      end
    end
  end
end
